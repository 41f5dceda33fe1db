"""ONNX export of trained networks and their CPU inference through onnxruntime, with the file's signature checked.

In: a torch module and an example input (export), or an .onnx file and the signature the code expects (OnnxModel);
out: the .onnx file, and numpy arrays from `OnnxModel.run`.
"""
from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from species.errors import TreefarmError

__all__ = ["OnnxModelError", "OnnxModel", "export_onnx", "OPSET", "BATCH_AXIS", "HEIGHT_AXIS", "WIDTH_AXIS"]

# One fixed opset, so a file exported today loads with the same operators in every onnxruntime >= 1.18.
OPSET = 17
BATCH_AXIS = "batch"
HEIGHT_AXIS, WIDTH_AXIS = "height", "width"
_ONNX_DTYPES = {"tensor(float)": "float32", "tensor(double)": "float64", "tensor(float16)": "float16",
                "tensor(int64)": "int64", "tensor(int32)": "int32", "tensor(uint8)": "uint8", "tensor(bool)": "bool"}

Signature = Mapping[str, Sequence[int | None]]


class OnnxModelError(TreefarmError):
    """An ONNX file is missing, unreadable, or its inputs and outputs differ from what the code expects."""


def _onnxruntime():
    try:
        import onnxruntime
    except ImportError:
        raise ImportError("trainers.onnx_runtime needs onnxruntime: pip install onnxruntime") from None
    return onnxruntime


def _torch():
    try:
        import torch
    except ImportError:
        raise ImportError("exporting to ONNX needs torch: pip install torch") from None
    return torch


def _tuple_outputs_module(model, output_names: Sequence[str]):
    """`model` with outputs as a tuple in `output_names` order (a network returning a dict of heads, e.g.
    TreeSketchNet, exports with those names)."""
    torch = _torch()

    class TupleOutputs(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.model = model

        def forward(self, *inputs):
            out = self.model(*inputs)
            if isinstance(out, Mapping):
                if set(out) != set(output_names):
                    raise OnnxModelError(f"the model returns outputs {sorted(out)} but output_names are "
                                         f"{list(output_names)}")
                return tuple(out[name] for name in output_names)
            return out

    return TupleOutputs()


def export_onnx(model, example_input, path: str | os.PathLike, input_names: Sequence[str],
                output_names: Sequence[str], spatial_axes: bool = False) -> Path:
    """Write `model` in eval mode to an ONNX file (TorchScript exporter, dynamo=False; opset OPSET; the first
    axis of every input and output named BATCH_AXIS and dynamic). The file appears whole or not at all.

    example_input : a tensor, or a tuple of tensors for several inputs, of the shape the file will expect.
    spatial_axes : also leave the last two axes (height and width, named HEIGHT_AXIS and WIDTH_AXIS) of every
    input and output dynamic, for a fully convolutional network that runs on images of any size.
    Returns the path written. The model's train/eval mode is restored afterwards.
    """
    torch = _torch()
    inputs = tuple(example_input) if isinstance(example_input, (tuple, list)) else (example_input,)
    input_names, output_names = list(input_names), list(output_names)
    if len(inputs) != len(input_names):
        raise OnnxModelError(f"{len(inputs)} example inputs but {len(input_names)} input names {input_names}")
    if not output_names or len(set(input_names + output_names)) != len(input_names) + len(output_names):
        raise OnnxModelError(f"input names {input_names} and output names {output_names} must be non-empty and "
                             f"distinct")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    was_training = model.training
    model.eval()
    fd, tmp = tempfile.mkstemp(suffix=".onnx.tmp", dir=path.parent)
    os.close(fd)
    try:
        with torch.no_grad(), warnings.catch_warnings():
            # The TorchScript exporter is chosen on purpose (fixed opset, plain dynamic_axes); its deprecation
            # notices are not news to a caller.
            warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"torch\.onnx.*")
            warnings.filterwarnings("ignore", message=".*legacy TorchScript-based ONNX export.*")
            torch.onnx.export(_tuple_outputs_module(model, output_names), inputs, tmp, input_names=input_names,
                              output_names=output_names, opset_version=OPSET, dynamo=False,
                              dynamic_axes={name: {0: BATCH_AXIS, **({2: HEIGHT_AXIS, 3: WIDTH_AXIS}
                                                                     if spatial_axes else {})}
                                            for name in input_names + output_names})
        os.replace(tmp, path)
    finally:
        model.train(was_training)
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def _shape_text(shape: Sequence) -> str:
    return "(" + ", ".join("B" if d is None or isinstance(d, str) else str(d) for d in shape) + ")"


def _check_signature(path: Path, kind: str, found, expected: Signature, dtype: str) -> None:
    """Compare the session's inputs or outputs (name, shape, type) with the expected names and shapes."""
    names = [arg.name for arg in found]
    if set(names) != set(expected):
        raise OnnxModelError(f"ONNX file {path} has {kind} {names}; the code expects {list(expected)}")
    for arg in found:
        want = list(expected[arg.name])
        have = list(arg.shape)
        # None in `want` takes any size; a symbolic (str) or unknown (None) axis in the file takes any size too.
        if len(have) != len(want) or any(w is not None and isinstance(h, int) and h != w
                                         for h, w in zip(have, want)):
            raise OnnxModelError(f"ONNX file {path}: {kind[:-1]} {arg.name!r} has shape {_shape_text(have)}; "
                                 f"the code expects {_shape_text(want)}")
        have_dtype = _ONNX_DTYPES.get(arg.type, arg.type)
        if have_dtype != dtype:
            raise OnnxModelError(f"ONNX file {path}: {kind[:-1]} {arg.name!r} has dtype {have_dtype}; the code "
                                 f"expects {dtype}")


class OnnxModel:
    """An ONNX file opened for CPU inference, its signature checked against what the code expects.

    path : the .onnx file.
    expected_inputs, expected_outputs : name -> shape, None for any size (the batch axis), e.g.
        {"sketch": (None, 1, 256, 256)}; the file must have exactly these names, ranks and fixed sizes.
    dtype : the element type of every input and output (float32).
    intra_op_threads : onnxruntime's intra-op threads (1: one core per model, as the farm's workers run).

    run(array) -> np.ndarray for a one-output model, else dict name -> np.ndarray. One input takes an array;
    several take a dict name -> array. Arrays are (B, ...) with the expected shape; floats are cast to float32.
    """

    def __init__(self, path: str | os.PathLike, expected_inputs: Signature, expected_outputs: Signature,
                 dtype: str = "float32", intra_op_threads: int = 1):
        ort = _onnxruntime()
        self.path = Path(path)
        if not self.path.is_file():
            raise OnnxModelError(f"ONNX file {self.path} does not exist")
        if isinstance(intra_op_threads, bool) or not isinstance(intra_op_threads, int) or intra_op_threads < 0:
            raise OnnxModelError(f"intra_op_threads = {intra_op_threads!r} is invalid: allowed an integer >= 0 "
                                 f"(0 = onnxruntime's default)")
        options = ort.SessionOptions()
        options.intra_op_num_threads = intra_op_threads
        options.inter_op_num_threads = 1
        state = ort.capi.onnxruntime_pybind11_state
        try:
            self.session = ort.InferenceSession(str(self.path), sess_options=options,
                                                providers=["CPUExecutionProvider"])
        except (state.InvalidProtobuf, state.InvalidGraph, state.Fail, state.NoSuchFile, state.NotImplemented,
                state.RuntimeException) as error:
            first_line = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
            raise OnnxModelError(f"ONNX file {self.path} cannot be loaded (corrupt or not an ONNX model): "
                                 f"{first_line}") from None
        self.dtype = np.dtype(dtype).name
        self.expected_inputs = {k: tuple(v) for k, v in expected_inputs.items()}
        self.expected_outputs = {k: tuple(v) for k, v in expected_outputs.items()}
        _check_signature(self.path, "inputs", self.session.get_inputs(), self.expected_inputs, self.dtype)
        _check_signature(self.path, "outputs", self.session.get_outputs(), self.expected_outputs, self.dtype)
        self.input_names = [arg.name for arg in self.session.get_inputs()]
        self.output_names = [arg.name for arg in self.session.get_outputs()]

    def _feed(self, name: str, array) -> np.ndarray:
        array = np.asarray(array)
        if not (np.issubdtype(array.dtype, np.floating) or array.dtype == np.dtype(self.dtype)):
            raise OnnxModelError(f"input {name!r} has dtype {array.dtype}; allowed {self.dtype} (or another float)")
        want = self.expected_inputs[name]
        if array.ndim != len(want) or any(w is not None and a != w for a, w in zip(array.shape, want)):
            raise OnnxModelError(f"input {name!r} has shape {array.shape}; allowed {_shape_text(want)}")
        return np.ascontiguousarray(array, dtype=self.dtype)

    def run(self, inputs) -> np.ndarray | dict[str, np.ndarray]:
        """Run the model; see the class docstring for what goes in and comes out."""
        if isinstance(inputs, Mapping):
            if set(inputs) != set(self.input_names):
                raise OnnxModelError(f"inputs {sorted(inputs)} given; the model takes {self.input_names}")
            feed = {name: self._feed(name, inputs[name]) for name in self.input_names}
        elif len(self.input_names) == 1:
            feed = {self.input_names[0]: self._feed(self.input_names[0], inputs)}
        else:
            raise OnnxModelError(f"the model takes several inputs {self.input_names}: pass a dict name -> array")
        outputs = self.session.run(self.output_names, feed)
        if len(outputs) == 1:
            return outputs[0]
        return dict(zip(self.output_names, outputs))

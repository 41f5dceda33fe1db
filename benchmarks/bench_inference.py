"""Inference time on ONE core of the networks reconstruction runs per sketch, torch against ONNX Runtime, by width.

Networks: the pix2pix U-Nets of both tasks (silhouette 1 -> 3 channels, trunk 3 -> 1) at each `--widths`, and
TreeSketchNet at its default size when `trainers.sketchnet` exists (skipped with a note otherwise). Weights are
untrained (timing does not depend on them); inputs are 256 px ink images, batch 1. torch runs with
torch.set_num_threads(1) under inference_mode; ONNX Runtime with intra_op_num_threads=1 (trainers.onnx_runtime).
Prints median (and min) ms per image per backend, then the per-sketch total of both U-Nets at one width plus
TreeSketchNet, each on its faster backend, against the issue's 0.5 s budget.
Run: python -m benchmarks.bench_inference [--widths 8,16,32,64] [--repeats 7]
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads, time_case

pin_threads()

import importlib.util  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from trainers.onnx_runtime import OnnxModel, export_onnx  # noqa: E402
from trainers.pix2pix import task_channels, task_generator  # noqa: E402
from trainers.tasks import TASKS  # noqa: E402

# The depth networks of the task registry, labelled as the tables name them (unet-silhouette, unet-trunk).
UNETS = {name.removeprefix("pix2pix-"): task for name, task in TASKS.items() if task.network == "pix2pix"}

BUDGET_MS = 500.0
SIZE = 256


def _times_ms(run, repeats: int) -> tuple[float, float]:
    """(median, min) ms of `run()` after two warm-up calls."""
    timing = time_case(run, repeats, warmup=2)
    return timing.ms(), 1000.0 * min(timing.wall)


def measure(net: torch.nn.Module, example: torch.Tensor, output_names: list[str], output_shapes: dict,
            folder: Path, repeats: int) -> dict:
    """Torch and ONNX Runtime timings of one network on `example` (1, C, S, S)."""
    net.eval()
    with torch.inference_mode():
        torch_median, torch_min = _times_ms(lambda: net(example), repeats)
    path = export_onnx(net, example, folder / "net.onnx", ["input"], output_names)
    model = OnnxModel(path, {"input": (None, *example.shape[1:])}, output_shapes)
    array = example.numpy()
    ort_median, ort_min = _times_ms(lambda: model.run(array), repeats)
    return {"params": sum(p.numel() for p in net.parameters()), "torch": torch_median, "torch_min": torch_min,
            "ort": ort_median, "ort_min": ort_min, "onnx_mb": path.stat().st_size / 2**20}


def sketchnet_case(rng: np.random.Generator):
    """(TreeSketchNet at its default size, its input, output names, output shapes), or a reason it is skipped."""
    if importlib.util.find_spec("trainers.sketchnet") is None:
        return "trainers.sketchnet does not exist yet"
    import species
    from trainers.sketchnet import TreeSketchNet
    from trainers.sketchnet_codec import ParameterCodec, weber_penn_species

    names = weber_penn_species()
    codec = ParameterCodec.fit([species.sample(name, rng) for name in names for _ in range(2)], names)
    try:
        net = TreeSketchNet(codec.head_sizes, codec.n_species, in_channels=1)
    except TypeError as error:
        return f"TreeSketchNet's constructor does not take (head_sizes, n_species, in_channels=1): {error}"
    example = torch.rand(1, 1, SIZE, SIZE, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        out = net.eval()(example)
    names = list(out)
    return net, example, names, {k: (None, *out[k].shape[1:]) for k in names}


def main() -> None:
    parser = arguments(__doc__, repeats=7)
    parser.add_argument("--widths", default="8,16,32,64", help="U-Net widths, comma separated")
    args = parser.parse_args()
    bench = Benchmark("inference", "Inference per sketch on one core: torch against ONNX Runtime", args)
    widths = [int(w) for w in args.widths.split(",")]
    torch.set_num_threads(1)
    torch.set_num_interop_threads(1)
    results: dict[tuple[str, int | str], dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name, task in UNETS.items():
            in_channels, out_channels = task_channels(task)
            for width in widths:
                net = task_generator(task, width=width, generator=torch.Generator().manual_seed(0))
                example = torch.rand(1, in_channels, SIZE, SIZE, generator=torch.Generator().manual_seed(1))
                out = {"output": (None, out_channels, SIZE, SIZE)}
                results[(f"unet-{name}", width)] = measure(net, example, ["output"], out, folder, args.repeats)
                print(f"  measured unet-{name} width {width}", flush=True)
        case = sketchnet_case(np.random.default_rng(0))
        if isinstance(case, str):
            bench.note(f"TreeSketchNet skipped: {case}")
        else:
            net, example, names, shapes = case
            results[("treesketchnet", "default")] = measure(net, example, names, shapes, folder, args.repeats)

    rows = []
    for (network, width), r in results.items():
        faster = "onnxruntime" if r["ort"] < r["torch"] else "torch"
        rows.append([network, str(width), f"{r['params'] / 1e6:.2f}", f"{r['onnx_mb']:.1f}", r["torch"],
                     r["torch_min"], r["ort"], r["ort_min"], f"{r['torch'] / r['ort']:.2f}x", faster])
    bench.table(f"ms per {SIZE} px image, batch 1, one core (median of {args.repeats}, and min)",
                ["network", "width", "M params", "ONNX MB", "torch ms", "torch min", "ORT ms", "ORT min",
                 "ORT speed-up", "faster"], rows)

    tsn = results.get(("treesketchnet", "default"))
    tsn_ms = min(tsn["torch"], tsn["ort"]) if tsn else 0.0
    rows = []
    for width in widths:
        pair = sum(min(results[(f"unet-{n}", width)]["torch"], results[(f"unet-{n}", width)]["ort"])
                   for n in UNETS)
        total = pair + tsn_ms
        rows.append([str(width), pair, tsn_ms if tsn else "skipped", total, "yes" if total < BUDGET_MS else "no"])
    bench.table(f"per sketch: both U-Nets at one width{' + TreeSketchNet' if tsn else ''}, faster backend each",
                ["U-Net width", "U-Nets ms", "TreeSketchNet ms", "total ms", "under budget"], rows,
                notes=[f"budget {BUDGET_MS:.0f} ms per sketch"])
    if 16 in widths:
        bench.figure("both U-Nets at width 16" + (" + TreeSketchNet" if tsn else ""),
                     next(row[3] for row in rows if row[0] == "16"), "ms per sketch", f"budget {BUDGET_MS:.0f} ms")
    bench.write()


if __name__ == "__main__":
    main()

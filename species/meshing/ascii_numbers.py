"""Vectorized ASCII text rows of numbers, byte-identical to Python's "%.6f" and "%d", for text mesh formats.

In: (R, K) float or int arrays and a row tag. Out: bytes, one "<tag> <n> <n> ...\\n" line per row, no Python loop.
"""
from __future__ import annotations

import numpy as np

from ..errors import TreefarmError

__all__ = ["fixed6_rows", "int_rows", "AsciiNumberError", "FIXED6_MAX_MAGNITUDE", "INT_MAX_MAGNITUDE"]

FIXED6_MAX_MAGNITUDE = 1e9  # |v| * 1e6 then stays below 2**53, where float64 holds every integer
INT_MAX_MAGNITUDE = 10**18 - 1  # |n| must fit int64 after abs()

# Text is built as little-endian 4-byte words, NUL-padded, and the NULs deleted at the end with one
# bytes.translate (one C pass). A word holds a group of three digits, looked up by the group's value;
# the first group of a number may carry its '-', and a number's last word keeps its fourth byte free for
# the separator (or newline) after it.
_WORD = np.dtype("<u4")
_ZERO, _NUL, _MINUS, _POINT = ord("0"), 0, ord("-"), ord(".")


def _digit_words() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Word tables: padded (1000,) "ddd"; point (1000,) ".ddd"; first (2000,) "d"/"dd"/"ddd" without leading
    zeros ("0" for 0) at value, the same after '-' at 1000 + value; leading (2000,) as first but "" for 0
    (a group before the number's first digit). All '<u4'."""
    value = np.arange(1000, dtype=np.uint32)
    hundreds, tens, ones = value // 100 + _ZERO, value // 10 % 10 + _ZERO, value % 10 + _ZERO
    padded = hundreds | tens << 8 | ones << 16
    unpadded = np.where(value >= 100, padded, np.where(value >= 10, tens | ones << 8, ones))
    first = np.concatenate([unpadded, _MINUS | unpadded << 8])
    leading = np.where(np.tile(value, 2) == 0, _NUL, first)
    point = _POINT | hundreds << 8 | tens << 16 | ones << 24
    return tuple(table.astype(_WORD) for table in (padded, point, first, leading))


_PADDED, _POINT_DIGITS, _FIRST, _LEADING = _digit_words()


class AsciiNumberError(TreefarmError):
    """A number that cannot be written as text here (not finite, or beyond the supported magnitude)."""


def _first_bad(values: np.ndarray, bad: np.ndarray, allowed: str) -> AsciiNumberError:
    index = int(np.flatnonzero(bad.ravel())[0])
    row, column = divmod(index, values.shape[1])
    return AsciiNumberError(f"value {values.ravel()[index].item()!r} (row {row}, column {column}) cannot be written: "
                            f"allowed {allowed}")


def _round_scaled(magnitude: np.ndarray) -> np.ndarray:
    """round(magnitude * 1e6), ties to even, on the exact product (as "%.6f" rounds the exact binary value).

    magnitude: (N,) float64 >= 0, < FIXED6_MAX_MAGNITUDE. Returns (N,) int64.
    A plain `rint(m * 1e6)` rounds the product first and is off by one for values within an ulp of a tie,
    so the product is carried exactly as total + error (Veltkamp split, Knuth two-sum) and the tie decided
    on the sign of (total - floor(total) - 0.5) + error, whose float sum keeps the exact sum's sign.
    """
    split = magnitude * 134217729.0  # 2**27 + 1: hi and lo get <= 26 significant bits each
    hi = split - (split - magnitude)
    lo = magnitude - hi
    product_hi, product_lo = hi * 1e6, lo * 1e6  # exact: 26 bits times 1e6 = 2**6 * 15625 (14 bits)
    total = product_hi + product_lo
    lo_part = total - product_hi
    error = (product_hi - (total - lo_part)) + (product_lo - lo_part)
    floor = np.floor(total)
    beyond_half = (total - floor - 0.5) + error
    rounded = floor.astype(np.int64)
    rounded += (beyond_half > 0) | ((beyond_half == 0) & (rounded % 2 == 1))
    return rounded


def _integer_words(magnitude: np.ndarray, negative: np.ndarray | None) -> np.ndarray:
    """(N, G) '<u4' words spelling `magnitude` ((N,) int64 >= 0) in decimal without leading zeros, three digits
    a word, G groups for the largest; words before a number's first digit are empty. Where `negative` ((N,)
    bool, or None) the first spelled word starts with '-'; that word may then fill all four bytes."""
    n_groups = max(1, -(-len(str(int(magnitude.max()))) // 3)) if len(magnitude) else 1
    groups = np.empty((n_groups, len(magnitude)), np.int64)
    rest = magnitude
    for group in range(n_groups - 1, 0, -1):  # over 3-digit groups, least significant first; not over values
        higher = rest // 1000
        groups[group] = rest - higher * 1000
        rest = higher
    groups[0] = rest
    sign_offset = 0 if negative is None else negative * 1000
    words = np.empty((len(magnitude), n_groups), _WORD)
    started = np.zeros(len(magnitude), bool)
    for group in range(n_groups):
        unstarted = (_LEADING if group < n_groups - 1 else _FIRST)[groups[group] + sign_offset]
        words[:, group] = np.where(started, _PADDED[groups[group]], unstarted) if group else unstarted
        started |= groups[group] != 0
    return words


def _join_rows(tag: str, fields: np.ndarray, separators: str) -> bytes:
    """Rows "<tag><separators[0]><field0><separators[1]><field1>...\\n" from fields (R, K, W) '<u4', each
    field's last word with its fourth byte free (written in place here). NUL bytes are dropped."""
    if not (tag.isascii() and tag.isprintable() and separators.isascii() and separators.isprintable()):
        raise AsciiNumberError(f"row tag {tag!r} and separators {separators!r} must be printable ASCII")
    n_rows = fields.shape[0]
    after_fields = np.frombuffer((separators[1:] + "\n").encode("ascii"), np.uint8).astype(_WORD)
    fields[:, :, -1] |= after_fields << 24
    head = (tag + separators[0]).encode("ascii")
    head_words = np.frombuffer(head + b"\0" * (-len(head) % 4), _WORD)
    lines = np.concatenate([np.broadcast_to(head_words, (n_rows, len(head_words))), fields.reshape(n_rows, -1)],
                           axis=1)
    return lines.tobytes().translate(None, b"\0")


def fixed6_rows(tag: str, values: np.ndarray) -> bytes:
    """One line "<tag> %.6f %.6f ...\\n" per row of `values`, byte-identical to Python's "%.6f".

    values: (R, K) float (any unit), |v| < FIXED6_MAX_MAGNITUDE and finite. Rounding is half-to-even on the
    exact binary value, as Python's (float32 values need no care there: their product with 1e6 is exact);
    negatives that round to zero keep their sign ("-0.000000"), as Python's.
    Raises AsciiNumberError naming the first value that is not finite or too large.
    """
    values = np.asarray(values)
    exact_product = values.dtype == np.float32  # 24 significant bits times 1e6 are exact in float64
    values = values.astype(np.float64, copy=False)
    if values.ndim != 2:
        raise AsciiNumberError(f"fixed6_rows needs (rows, columns) values; got shape {values.shape}")
    if values.size == 0:
        return b""
    magnitude = np.abs(values).ravel()
    bad = ~(magnitude < FIXED6_MAX_MAGNITUDE)  # NaN compares False, so it is caught here too
    if bad.any():
        raise _first_bad(values, bad, f"finite numbers with |v| < {FIXED6_MAX_MAGNITUDE:,.0f}")
    scaled = np.rint(magnitude * 1e6).astype(np.int64) if exact_product else _round_scaled(magnitude)
    integer = scaled // 10**6
    fraction = (scaled - integer * 10**6).astype(np.int32)
    first_three = fraction // 1000
    fields = np.concatenate([_integer_words(integer, np.signbit(values.ravel())), _POINT_DIGITS[first_three][:, None],
                             _PADDED[fraction - first_three * 1000][:, None]], axis=1)
    return _join_rows(tag, fields.reshape(*values.shape, -1), " " * values.shape[1])


def int_rows(tag: str, values: np.ndarray, separators: str) -> bytes:
    """One line "<tag><separators[0]>%d<separators[1]>%d...\\n" per row of `values`, as Python's "%d".

    values: (R, K) integer, |n| <= INT_MAX_MAGNITUDE; separators: K printable ASCII characters, the k-th
    written before column k (e.g. " // // //" for OBJ faces "f a/a/a b/b/b c/c/c").
    Values that span a range no wider than their count (mesh indices) are spelled once per distinct
    value of the range and gathered.
    """
    values = np.asarray(values)
    if values.ndim != 2 or not np.issubdtype(values.dtype, np.integer):
        raise AsciiNumberError(f"int_rows needs (rows, columns) integers; got {values.dtype} of shape {values.shape}")
    if len(separators) != values.shape[1]:
        raise AsciiNumberError(f"int_rows got {len(separators)} separators {separators!r} for "
                               f"{values.shape[1]} columns: allowed one per column")
    if values.size == 0:
        return b""
    bad = (values > INT_MAX_MAGNITUDE) | (values < -INT_MAX_MAGNITUDE)
    if bad.any():
        raise _first_bad(values, bad, f"integers with |n| <= {INT_MAX_MAGNITUDE:,}")
    flat = values.ravel().astype(np.int64)
    low, high = int(flat.min()), int(flat.max())
    spelled = np.arange(low, high + 1) if high - low < flat.size else flat
    spelled_fields = _integer_words(np.abs(spelled), None)
    if low < 0:  # a word of its own for '-', so that each field's last word keeps a free byte
        spelled_fields = np.concatenate([((spelled < 0) * _MINUS).astype(_WORD)[:, None], spelled_fields], axis=1)
    if spelled is not flat:  # gather whole fields, as one opaque item each
        field_item = np.dtype((np.void, spelled_fields.shape[1] * _WORD.itemsize))
        spelled_fields = spelled_fields.view(field_item)[flat - low].view(_WORD)
    return _join_rows(tag, spelled_fields.reshape(*values.shape, -1), separators)

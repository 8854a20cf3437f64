"""Compare a rebuilt report file with the committed one, to the digits a report means.

A report is recomputed on the reader's machine from its archived rows; BLAS kernels and CPUs
differ in the last bits of a float, so byte equality of computed floats is a property of one
machine, not of the code (a fresh machine rewrote ``sharp_limit.json`` with ``order_e``
1.5264050679115821 against …813). The tolerances, stated once:

* JSON: the same structure, keys, strings and integers; floats equal to
  :data:`JSON_RTOL` relative (or :data:`JSON_ATOL` absolute, for values that should be 0).
* Text (Markdown, CSV, TOML, …): the same words; each number printed with a decimal point or
  an exponent equal to within one unit of its last printed digit (a value on a rounding
  boundary may print either way) or :data:`JSON_RTOL` relative; integers exactly (counts such
  as "57 of 64" never move by rounding).
* PNG: the same bytes, or the same size and at most :data:`PNG_PIXELS` of the pixels
  differing by more than :data:`PNG_LEVEL` in a channel (a stale figure moves far more).

:func:`differences` returns what differs, in words (empty: the files agree).
"""

from __future__ import annotations

import json
import math
import re

JSON_RTOL = 1e-9
JSON_ATOL = 1e-12
PNG_PIXELS = 2e-4
PNG_LEVEL = 16

#: a number in text: sign, digits with an optional fraction, an optional exponent; not part
#: of a word (v2, x86_64) — a letter or an underscore before it keeps it text
NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?(?![\w])")


def _is_float_text(token: str) -> bool:
    return any(ch in token for ch in ".eE")


def _last_digit_unit(token: str) -> float:
    """One unit of the last printed digit of a decimal token (1e-3 for 4.452, 1e-5 for
    1.2e-3 → mantissa 1.2, exponent −3: 0.1 × 1e-3)."""
    mantissa, _, exponent = token.lower().partition("e")
    mantissa = mantissa.lstrip("+-")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return 10.0 ** (-decimals + (int(exponent) if exponent else 0))


def numbers_agree(a: str, b: str) -> bool:
    """Two printed numbers are the same value to the digits printed (module docstring)."""
    if a == b:
        return True
    if not (_is_float_text(a) and _is_float_text(b)):
        return False  # integers exactly
    x, y = float(a), float(b)
    if math.isclose(x, y, rel_tol=JSON_RTOL, abs_tol=JSON_ATOL):
        return True
    unit = max(_last_digit_unit(a), _last_digit_unit(b))
    return abs(x - y) <= unit * (1.0 + 1e-9)


def text_differences(a: str, b: str, where: str = "") -> list[str]:
    """The lines of two texts that differ beyond the tolerance of printed numbers."""
    la, lb = a.splitlines(), b.splitlines()
    if len(la) != len(lb):
        return [f"{where}{len(la)} lines against {len(lb)}"]
    out = []
    for k, (x, y) in enumerate(zip(la, lb, strict=True), 1):
        if x == y:
            continue
        nx, ny = NUMBER.findall(x), NUMBER.findall(y)
        words_x, words_y = NUMBER.sub("#", x), NUMBER.sub("#", y)
        if words_x != words_y or len(nx) != len(ny) or not all(
                numbers_agree(p, q) for p, q in zip(nx, ny, strict=True)):
            out.append(f"{where}line {k}: {x.strip()[:120]!r} -> {y.strip()[:120]!r}")
    return out


def json_differences(a, b, path: str = "$") -> list[str]:
    """Where two parsed JSON values differ beyond the tolerance (module docstring)."""
    if isinstance(a, dict) and isinstance(b, dict):
        if list(a) != list(b):
            return [f"{path}: keys {sorted(set(a) ^ set(b)) or 'in another order'}"]
        return [d for key in a for d in json_differences(a[key], b[key], f"{path}.{key}")]
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} items against {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in json_differences(x, y, f"{path}[{i}]")]
    if isinstance(a, float) or isinstance(b, float):
        if isinstance(a, bool) or isinstance(b, bool) or not isinstance(a, int | float) \
                or not isinstance(b, int | float):
            return [f"{path}: {a!r} -> {b!r}"]
        if (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=JSON_RTOL,
                                                             abs_tol=JSON_ATOL):
            return []
        return [f"{path}: {a!r} -> {b!r}"]
    if isinstance(a, str) and isinstance(b, str):
        return text_differences(a, b, f"{path}: ") if a != b else []
    return [] if (type(a) is type(b) and a == b) else [f"{path}: {a!r} -> {b!r}"]


def png_differences(a: bytes, b: bytes) -> list[str]:
    if a == b:
        return []
    import io

    import numpy as np
    from PIL import Image

    x = np.asarray(Image.open(io.BytesIO(a)).convert("RGB"), dtype=int)
    y = np.asarray(Image.open(io.BytesIO(b)).convert("RGB"), dtype=int)
    if x.shape != y.shape:
        return [f"size {x.shape[1]}x{x.shape[0]} -> {y.shape[1]}x{y.shape[0]}"]
    moved = int(np.count_nonzero(np.abs(x - y).max(axis=2) > PNG_LEVEL))
    if moved > PNG_PIXELS * x.shape[0] * x.shape[1]:
        return [f"{moved} of {x.shape[0] * x.shape[1]} pixels differ"]
    return []


def differences(name: str, a: bytes, b: bytes) -> list[str]:
    """What differs between the committed file ``a`` and the rebuilt ``b`` of file ``name``
    (by its suffix), beyond the tolerances of the module docstring."""
    if a == b:
        return []
    if name.endswith(".png"):
        return png_differences(a, b)
    try:
        ta, tb = a.decode(), b.decode()
    except UnicodeDecodeError:
        return ["binary files differ"]
    if name.endswith(".json"):
        try:
            return json_differences(json.loads(ta), json.loads(tb))
        except json.JSONDecodeError as exc:
            return [f"not JSON: {exc}"]
    return text_differences(ta, tb)

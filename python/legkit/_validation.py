"""Argument checks shared by the Python packages: every error names the offending argument.

Wrong types raise TypeError and wrong values (shape, range, NaN/inf) ValueError; a check changes no state.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import tempfile
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TypeGuard

import numpy as np
import numpy.typing as npt

UNIT_TOLERANCE = 1e-6


def is_integer(value: object) -> TypeGuard[int | np.integer]:
    """True for a Python or numpy integer; False for a bool, which Python counts as an int."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def integer(value: object, name: str) -> int:
    """`value` as an int: TypeError unless it is a Python or numpy integer (bools refused)."""
    if not is_integer(value):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    return int(value)


def instance(value: object, kind: type, name: str) -> None:
    """TypeError naming `name` unless `value` is a `kind`."""
    if not isinstance(value, kind):
        raise TypeError(f"{name} must be a {kind.__name__}, got {type(value).__name__}")


def choice(value: object, options: Sequence[object], name: str) -> None:
    """ValueError naming `name` unless `value` is one of `options`."""
    if isinstance(value, (list, np.ndarray)) or not any(value == option for option in options):
        raise ValueError(f"{name} must be one of {tuple(options)}, got {value!r}")


def count(value: object, name: str, low: int, high: int | None = None) -> int:
    """`value` as an int in [low, high] (no upper end when high is None): TypeError unless it is an integer, ValueError
    naming `name` outside the range."""
    number = integer(value, name)
    if number < low or (high is not None and number > high):
        raise ValueError(f"{name} must be in [{low}, {'inf' if high is None else high}], got {number}")
    return number


def is_real(value: object) -> TypeGuard[int | float | np.integer | np.floating]:
    """True for a Python or numpy real scalar; False for a bool."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def positive_scalar(value: object, name: str, *, allow_zero: bool = False) -> float:
    """A finite real scalar > 0 (or >= 0 with allow_zero): TypeError if it is not a real number (bools refused)."""
    if not is_real(value):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    number = float(value)
    if not np.isfinite(number) or number < 0.0 or (number == 0.0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {bound}, got {value}")
    return number


def unmasked(value: object, name: str) -> None:
    """ValueError if `value` is a masked array with masked entries, whose hidden values NumPy would read."""
    if np.ma.is_masked(value):
        raise ValueError(f"{name} is a masked array with masked entries (fill them first: a.filled(value))")


def real_numbers(value: object, name: str) -> np.ndarray:
    """`value` as a float64 array, where NumPy reads it as real numbers (any real dtype, byte order, layout or
    sequence: the same numbers as a plain float64 array); TypeError where NumPy would make numbers of what is not
    (complex, dropping the imaginary part with only a warning; strings; dates; records), ValueError for a masked array
    with masked entries (NumPy reads the hidden values) and for an int beyond float64's range. NaN and inf pass."""
    unmasked(value, name)
    try:
        array = np.asarray(value)
        if array.dtype.kind not in "biufO":
            raise TypeError(f"{name} must be an array of numbers, got an array of {array.dtype}: only real numbers are taken")
        return np.asarray(array, dtype=np.float64)
    except OverflowError as error:
        raise ValueError(f"{name} holds a number beyond float64's range") from error
    except (TypeError, ValueError) as error:
        if str(error).startswith(name):
            raise
        raise TypeError(f"{name} must be an array of real numbers, got {type(value).__name__}") from error


def float_array(
    value: object, name: str, *, shape: tuple[int, ...] | None = None, last: int | None = None, min_ndim: int = 0,
    bound: float | None = None,
) -> np.ndarray:
    """`value` as a finite float64 array: TypeError if it is not numeric, ValueError on a wrong shape
    (other than `shape`, fewer than `min_ndim` dimensions, or a last dimension other than `last`), on NaN/inf, or
    on an entry beyond +-`bound` (where squares and products of the values would overflow to NaN)."""
    array = real_numbers(value, name)
    if shape is not None and array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {array.shape}")
    if array.ndim < min_ndim:
        raise ValueError(f"{name} must have at least {min_ndim} dimensions, got shape {array.shape}")
    if last is not None and (array.ndim == 0 or array.shape[-1] != last):
        raise ValueError(f"{name} must have a last dimension of size {last}, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains a non-finite value (NaN or inf)")
    if bound is not None and array.size and np.max(np.abs(array)) > bound:
        raise ValueError(f"{name} must lie within +-{bound:g}, got {np.max(np.abs(array)):g}")
    return array


#: Largest magnitude of a robot's length (m) or mass (kg) parameter: a product such as m l^2 of two stays finite.
MAX_PARAMETER = 1e100


def parameter_fields(
    parameters: object, *, positive: Iterable[str] = (), non_negative: Iterable[str] = (), real: Iterable[str] = ()
) -> None:
    """Checks a parameter dataclass's fields by name: each a real number or, where the field's default is a tuple,
    a tuple of as many; finite and within +-MAX_PARAMETER; > 0 for `positive`, >= 0 for `non_negative`
    (TypeError or ValueError naming the field)."""
    defaults = {f.name: f.default for f in dataclasses.fields(parameters)}  # type: ignore[arg-type]
    for names, low in ((positive, "> 0"), (non_negative, ">= 0"), (real, None)):
        for name in names:
            value = getattr(parameters, name)
            default = defaults[name]
            shape = (len(default),) if isinstance(default, tuple) else ()
            if isinstance(value, (str, bytes)):
                raise TypeError(f"{name} must be {'a real number' if not shape else f'{shape[0]} real numbers'}, got {type(value).__name__}")
            array = float_array(value, name, shape=shape, bound=MAX_PARAMETER)
            if (low == "> 0" and np.any(array <= 0.0)) or (low == ">= 0" and np.any(array < 0.0)):
                raise ValueError(f"{name} must be {low}, got {value}")


def check_allocation(n_bytes: int, name: str) -> None:
    """MemoryError naming `name` when `n_bytes` exceed this machine's physical memory: NumPy would reserve them
    lazily, and the process be killed once it had written that much."""
    available = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    if n_bytes > available:
        raise MemoryError(f"{name}: needs {n_bytes / 1e9:.3g} GB, more than this machine's memory ({available / 1e9:.3g} GB)")


def zeros(shape: tuple[int, ...], name: str) -> np.ndarray:
    """np.zeros(shape), or a MemoryError naming `name` when it cannot be had."""
    check_allocation(8 * math.prod(shape), name)
    try:
        return np.zeros(shape)
    except MemoryError:
        raise MemoryError(f"{name}: {shape} needs {8 * math.prod(shape) / 1e9:.3g} GB, more than can be allocated") from None


def bool_mask(value: npt.ArrayLike | None, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """A boolean mask broadcast to `shape` (all True when `value` is None)."""
    if value is None:
        return np.ones(shape, dtype=bool)
    mask = np.asarray(value)
    if mask.dtype != bool:
        raise TypeError(f"{name} must be a boolean array, got dtype {mask.dtype}")
    try:
        return np.broadcast_to(mask, shape)
    except ValueError as error:
        raise ValueError(f"{name} has shape {mask.shape}, which does not broadcast to {shape}") from error


def friction_coefficient(mu: npt.ArrayLike, name: str = "mu") -> np.ndarray:
    """Friction coefficient(s): finite and >= 0."""
    array = float_array(mu, name)
    if np.any(array < 0.0):
        raise ValueError(f"{name} must be >= 0, got {array.min()}")
    return array


def unit_vectors(value: npt.ArrayLike, name: str) -> np.ndarray:
    """(..., 3) vectors that must already be unit length (to 1e-6): a non-unit normal is a caller bug."""
    array = float_array(value, name, last=3)
    norms = np.linalg.norm(array, axis=-1)
    if np.any(np.abs(norms - 1.0) > UNIT_TOLERANCE):
        worst = norms.flat[np.argmax(np.abs(norms - 1.0))]
        raise ValueError(f"{name} must be unit vectors (|n| = 1 within {UNIT_TOLERANCE}), found |n| = {worst:.9g}")
    return array


def time_grid(t: npt.ArrayLike, samples: int, name: str = "t") -> np.ndarray:
    """Strictly increasing sample times matching `samples` values along the first axis."""
    times = float_array(t, name)
    if times.ndim != 1 or times.shape[0] != samples:
        raise ValueError(f"{name} must be 1-D with {samples} samples, got shape {times.shape}")
    if samples < 2:
        raise ValueError(f"{name} needs at least two samples to integrate over, got {samples}")
    if np.any(np.diff(times) <= 0.0):
        raise ValueError(f"{name} must be strictly increasing")
    return times


def bounded_float(low: float, high: float, *, open_low: bool = False, open_high: bool = False) -> Callable[[str], float]:
    """An argparse type: a number in [low, high] (an end excluded with `open_low` or `open_high`); NaN is refused."""
    interval = f"{'(' if open_low else '['}{low:g}, {high:g}{')' if open_high else ']'}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text[:40]!r}") from None
        above = value > low if open_low else value >= low
        below = value < high if open_high else value <= high
        if not (above and below):
            raise argparse.ArgumentTypeError(f"must be in {interval}, got {text[:40]}")
        return value

    return parse


def bounded_int(low: int, high: int) -> Callable[[str], int]:
    """An argparse type: an integer in [low, high], so that a command refuses a huge count on one line
    instead of running out of memory or time."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text[:40]!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be in [{low}, {high}], got {text[:40]}")
        return value

    return parse


def output_folder(path: Path) -> Path:
    """`path`, created if needed, after checking that a file can be written in it, so that a command can check
    its output folder before it runs rather than fail after. ValueError saying why otherwise."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as error:
        raise ValueError(f"cannot write to {str(path)!r}: {error.strerror or error}") from None
    return path


def output_folder_argument(text: str) -> Path:
    """An argparse type: `output_folder`, checked as the command line is read (before the command runs)."""
    try:
        return output_folder(Path(text))
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


#: Every ``legkit`` command that writes files writes them to ``--out DIR``, by default ``legkit-out/<command>``
#: in the working folder.
OUTPUT_ROOT = Path("legkit-out")


def add_output_folder(parser: argparse.ArgumentParser, command: str, what: str, checked: bool = True) -> None:
    """The ``--out`` option of ``legkit <command>``: the folder ``what`` goes to, by default
    ``legkit-out/<command>``; ``checked`` (default): created and checked writable as the command line is read."""
    default = OUTPUT_ROOT / command
    parser.add_argument(
        "--out", type=output_folder_argument if checked else Path, default=str(default),
        help=f"folder for {what} (default ./{default})",
    )

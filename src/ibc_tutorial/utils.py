"""Small shared helpers: seeding, quiet mode, argument checks, devices, atomic writes."""

from __future__ import annotations

import io
import os
import random
import tempfile
from collections.abc import Iterable
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

QUIET_ENV = "TQDM_DISABLE"
"""tqdm's own switch: set it to 1 (``conftest.py`` and ``tools/execute_notebooks.py`` do) to
silence progress bars, so that stored notebook outputs do not depend on timing."""


WORKER_SLOT_ENV = "IBC_TUTORIAL_WORKER_SLOT"
"""Set in each worker process of ``parallel`` to its slot (0, 1, ...): the line its progress bar takes on
the terminal, so that two workers' bars stand on two lines instead of overwriting each other."""


def seed_everything(seed: int) -> torch.Generator:
    """Seed Python, NumPy and torch, make torch deterministic, and return a seeded generator.

    Chapters call this in their first cell so that every number they print is reproducible.
    """
    check_int("seed", seed, minimum=0)
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True, warn_only=True)
    return torch.Generator().manual_seed(seed)


def quiet() -> bool:
    """True when ``TQDM_DISABLE`` is set (to anything but 0 / false): under the tests and the
    notebook executor.

    Read here at each call rather than left to tqdm: tqdm reads its ``TQDM_*`` variables once,
    when it is first imported, and its notebook bar (what ``tqdm.auto`` gives in Jupyter) passes
    ``disable=False`` explicitly, which overrides the variable (tqdm 4.70)."""
    return os.environ.get(QUIET_ENV, "").strip().lower() not in ("", "0", "false")


def progress(
    iterable: Iterable | None = None, *, total: int | None = None, desc: str = "", enabled: bool | None = None
):
    """A tqdm progress bar for readers; a silent pass-through when ``TQDM_DISABLE=1`` (see
    ``quiet``) or ``enabled`` is False. In a worker process (whose ``TQDM_DISABLE`` is set) a bar shows only
    if ``enabled`` is True, on the worker's own line (``WORKER_SLOT_ENV``)."""
    show = (not quiet()) if enabled is None else enabled
    slot = os.environ.get(WORKER_SLOT_ENV)  # in a worker process: its own line
    position = int(slot) if slot is not None else None
    return tqdm(iterable, total=total, desc=desc, disable=not show, leave=False, position=position)


def plural(n: int, word: str) -> str:
    """``n`` and ``word``, with an s unless ``n`` is 1: "1 run", "3 runs"."""
    return f"{n} {word}" + ("" if n == 1 else "s")


# --------------------------------------------------------------------------- argument checks
def check_int(name: str, value, *, minimum: int | None = None, maximum: int | None = None) -> int:
    """Return ``value`` as an int, or raise ValueError naming ``name`` and the expected range."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {value}")
    return value


def check_positive(name: str, value, *, allow_zero: bool = False) -> float:
    """Return ``value`` as a finite float > 0 (or >= 0), or raise ValueError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ValueError(f"{name} must be a finite number {'>=' if allow_zero else '>'} 0, got {value!r}")
    return v


def check_positive_fields(
    config, names: Iterable[str], *, allow_zero: bool = False, prefix: str = "config"
) -> None:
    """``check_positive`` on each field ``names`` of a config dataclass; the error names
    ``config.<field>`` (``prefix`` changes the first part)."""
    for name in names:
        check_positive(f"{prefix}.{name}", getattr(config, name), allow_zero=allow_zero)


def _check_unit_interval(name: str, value, what: str) -> float:
    """``value`` as a float in [0, 1], or ValueError naming ``name`` and saying what it must be."""
    try:
        if isinstance(value, (str, bytes)):  # "0.5" is text, not a number: refused, not converted
            raise TypeError
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {what} in [0, 1], got {value!r}") from None
    if not 0.0 <= v <= 1.0:  # also rejects NaN
        raise ValueError(f"{name} must be {what} in [0, 1], got {value!r}")
    return v


def check_probability(name: str, value) -> float:
    """Return ``value`` as a float in [0, 1], or raise ValueError naming ``name``."""
    return _check_unit_interval(name, value, "a probability")


def check_fraction(name: str, value) -> float:
    """Return ``value`` as a float in [0, 1] (a share or a scale, not a probability).

    Raise ValueError naming ``name`` otherwise."""
    return _check_unit_interval(name, value, "a fraction")


def check_choice(name: str, value, choices: Iterable) -> str:
    """Raise ValueError naming ``name`` unless ``value`` is one of ``choices``."""
    choices = tuple(choices)
    if value not in choices:
        raise ValueError(f"{name} must be one of {choices}, got {value!r}")
    return value


_VALUE_CHECKS = [True]  # a list, so that the context manager below can switch it in place


def value_checks_on() -> bool:
    """Whether the checks that read a tensor's values (finite, inside a range) run: yes, except inside
    ``without_value_checks``."""
    return _VALUE_CHECKS[-1]


@contextmanager
def without_value_checks():
    """Inside, ``check_tensor`` and the losses skip the checks that read a tensor's values (finite,
    inside [-1, 1], positive): ``torch.vmap`` cannot branch on a value. Shapes are still checked. The
    caller checks the values once before (``stacked_training.train_stacked`` checks its data)."""
    _VALUE_CHECKS.append(False)
    try:
        yield
    finally:
        _VALUE_CHECKS.pop()


def check_tensor(
    name: str, x, *, ndim: int | None = None, shape: tuple | None = None, finite: bool = True
) -> torch.Tensor:
    """Check a tensor's rank, shape (``None`` entries are free) and finiteness.

    Raise ValueError naming ``name`` otherwise."""
    if not isinstance(x, torch.Tensor):
        raise ValueError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    if ndim is not None and x.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimensions, got shape {tuple(x.shape)}")
    if shape is not None:
        if x.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, x.shape, strict=True)):
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{name} must have shape {want}, got {tuple(x.shape)}")
    if finite and value_checks_on() and x.is_floating_point() and not torch.isfinite(x).all():
        raise ValueError(f"{name} must be finite, got NaN or inf")
    return x


def check_box(
    low, high, d: int | None = None, *, name: str = "", dtype: torch.dtype | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """The action box [low, high] as two (D,) tensors: the one check of action bounds in the library.

    ``low`` and ``high`` are numbers, or sequences, arrays or tensors with one number per action
    dimension; a single number stands for every dimension. D is ``d`` if given, else the longer
    of the two. ValueError naming ``low`` or ``high`` (after ``name: `` if given, e.g. "bounds")
    unless each holds 1 or D finite numbers and low < high in every dimension.

    Returns copies in ``dtype`` (torch's default dtype if None), on the CPU.
    """
    prefix = f"{name}: " if name else ""
    dtype = torch.get_default_dtype() if dtype is None else dtype
    out = []
    for arg, v in (("low", low), ("high", high)):
        try:
            t = torch.as_tensor(v.tolist() if hasattr(v, "tolist") else v, dtype=dtype).reshape(-1)
        except (TypeError, ValueError, RuntimeError):
            raise ValueError(f"{prefix}{arg} must be a number or a sequence of numbers, got {v!r}") from None
        if t.numel() == 0:
            raise ValueError(f"{prefix}{arg} must hold at least one number")
        if not torch.isfinite(t).all():
            raise ValueError(f"{prefix}{arg} must be finite numbers, got {t.tolist()}")
        out.append(t)
    lo, hi = out
    n = max(len(lo), len(hi)) if d is None else d
    for arg, t in (("low", lo), ("high", hi)):
        if t.numel() not in (1, n):
            if d is None:
                raise ValueError(
                    f"{prefix}low and high must have the same length D (or one be a single number), "
                    f"got {len(lo)} and {len(hi)}"
                )
            raise ValueError(
                f"{prefix}{arg} must be a number or have one entry per action dimension (D = {n}), "
                f"got {t.numel()} entries"
            )
    lo, hi = lo.expand(n).clone(), hi.expand(n).clone()  # (D,), (D,)
    if not (lo < hi).all():
        raise ValueError(
            f"{prefix}low must be < high in every action dimension, got low={lo.tolist()}, high={hi.tolist()}"
        )
    return lo, hi


# --------------------------------------------------------------------------- devices
DEVICE_TYPES = ("cpu", "cuda", "mps")
"""Device types ``check_device`` accepts: the CPU, an NVIDIA GPU (``cuda`` or ``cuda:N``), Apple's ``mps``."""


def check_device(name: str, device) -> torch.device:
    """Return ``device`` (a name such as "cpu", "cuda", "cuda:1", "mps", or a ``torch.device``) as a
    ``torch.device`` that exists on this machine; ValueError naming ``name`` otherwise: a name that is not
    a torch device, a type other than ``DEVICE_TYPES``, CUDA or MPS unavailable, a GPU index beyond the
    GPUs present."""
    if isinstance(device, torch.device):
        dev = device
    elif isinstance(device, str):
        try:
            dev = torch.device(device)
        except (RuntimeError, ValueError):
            raise ValueError(
                f"{name} must be a torch device name such as 'cpu', 'cuda', 'cuda:1' or 'mps', got {device!r}"
            ) from None
    else:
        raise ValueError(f"{name} must be a device name such as 'cpu' or 'cuda', got {device!r}")
    if dev.type not in DEVICE_TYPES:
        raise ValueError(f"{name} must be one of {DEVICE_TYPES} (cuda:N for the N-th GPU), got {device!r}")
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            why = (
                f"this torch, {torch.__version__}, is built without CUDA: install a CUDA build of torch"
                if torch.version.cuda is None
                else "no CUDA GPU is visible"
            )
            raise ValueError(
                f"{name} {device!r}: CUDA is not available on this machine ({why}), or use {name} cpu"
            )
        n = torch.cuda.device_count()
        if dev.index is not None and dev.index >= n:
            raise ValueError(f"{name} {device!r}: this machine has {n} CUDA GPU(s), cuda:0 to cuda:{n - 1}")
    if dev.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"{name} {device!r}: Apple's MPS is not available on this machine: use {name} cpu")
    return dev


def draw_device(generator: torch.Generator | None) -> torch.device:
    """Where random draws with ``generator`` are made: its own device (the CPU for None, torch's global
    generator). Library code draws there and then moves the result (``.to(device)``) to the tensors it
    works with, so a run on a GPU draws the same numbers from the same seeded CPU generator as on the CPU."""
    return generator.device if generator is not None else torch.device("cpu")


# --------------------------------------------------------------------------- files
def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically: a temporary file in the same folder, then rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_torch_save(obj, path: str | os.PathLike) -> Path:
    """``torch.save`` to ``path`` atomically (load back with ``torch.load(..., weights_only=True)``)."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    return atomic_write_bytes(path, buf.getvalue())

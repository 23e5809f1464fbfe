#!/usr/bin/env python
"""Find stored outputs that another CPU would not reproduce: run notebooks as several CPUs would.

    python tools/find_fragile_outputs.py book/03_energy_models.ipynb
    python tools/find_fragile_outputs.py book/02_explicit_policies.ipynb --settings native-1,older-cpu
    python tools/find_fragile_outputs.py --list-settings

Each notebook is executed top to bottom in a fresh kernel once per *setting*: an environment that
changes which instruction sets PyTorch, MKL and oneDNN use and how many threads they use, so that
floating-point sums are taken in other orders, as they are on other CPUs (a machine with AVX-512
blocks its matrix products differently from one with AVX2, and both from one thread of SSE4.2).
Executed copies go to a temporary folder (`--keep DIR` keeps them there); the notebook on disk is
never changed. Each code cell's text outputs under each setting are compared with the stored ones,
as `pytest --nbval` compares them: streams and text data (images skipped), after the replacements of
tools/nbval_sanitize.cfg; cells marked `# NBVAL_IGNORE_OUTPUT` or `# NBVAL_SKIP` are left out. A cell
that raises under a setting (a failed assert) counts as a difference; execution goes on with the next
cell; an execution that cannot finish (a cell over --timeout, a dead kernel) is reported as failed.
The table lists every cell whose text differs under any setting, with the first line that differs;
the exit code is 1 when there is one or an execution failed, 0 when every setting printed the stored
outputs.

Cells are numbered as nbval numbers them: code cells only, from 0. A difference under one setting
is enough to change a cell: print fewer digits, a count with a margin, or an assert instead of a
number (CONTRIBUTING.md). A clean run is evidence, not proof: the settings imitate some CPUs, not
all of them, and a value close to a rounding edge may still tip on a CPU that none of them imitates.
Run one notebook at a time on a busy machine: every setting is a full execution.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SANITIZE_CFG = ROOT / "tools" / "nbval_sanitize.cfg"

# the older CPU of CONTRIBUTING.md and CI: no AVX in ATen, SSE4.2 in MKL, SSE4.1 in oneDNN
OLDER_CPU = {
    "ATEN_CPU_CAPABILITY": "default",
    "MKL_ENABLE_INSTRUCTIONS": "SSE4_2",
    "ONEDNN_MAX_CPU_ISA": "SSE41",
}
# name: (environment added to this process's, what it imitates)
SETTINGS: dict[str, tuple[dict[str, str], str]] = {
    "native-2": ({"OMP_NUM_THREADS": "2"}, "this CPU, two threads (workers as configured)"),
    "native-1": ({"OMP_NUM_THREADS": "1"}, "this CPU, one thread"),
    "older-cpu": (
        {**OLDER_CPU, "OMP_NUM_THREADS": "1", "IBC_TUTORIAL_WORKERS": "1"},
        "an older CPU, one thread, seed sweeps in-process (CI's emulated pass)",
    ),
    "avx2": (
        {"ATEN_CPU_CAPABILITY": "avx2", "MKL_ENABLE_INSTRUCTIONS": "AVX2", "OMP_NUM_THREADS": "1"},
        "AVX2 in ATen and MKL, one thread",
    ),
    "mkl-avx": ({"MKL_ENABLE_INSTRUCTIONS": "AVX", "OMP_NUM_THREADS": "1"}, "MKL limited to AVX, one thread"),
    "mkl-compatible": (
        {"MKL_CBWR": "COMPATIBLE", "OMP_NUM_THREADS": "1"},
        "MKL's conditional numerical reproducibility (its portable code path), one thread",
    ),
}
DEFAULT_SETTINGS = ("native-1", "older-cpu", "avx2", "mkl-avx")
IGNORE_MARKERS = ("NBVAL_IGNORE_OUTPUT", "NBVAL_SKIP")
# what nbval does not compare (its skip_compare without --nbdime)
SKIPPED_KEYS = {
    "metadata",
    "traceback",
    "prompt_number",
    "output_type",
    "name",
    "execution_count",
    "application/vnd.jupyter.widget-view+json",
    "image/png",
    "image/jpeg",
}


def load_sanitizers(path: Path = SANITIZE_CFG) -> list[tuple[re.Pattern[str], str]]:
    """The (regex, replacement) pairs of an nbval sanitize file ("regex: ..." then "replace: ...")."""
    rules, pattern = [], None
    for line in path.read_text().splitlines():
        if line.startswith("regex:"):
            pattern = re.compile(line[len("regex:") :].strip())
        elif line.startswith("replace:") and pattern is not None:
            rules.append((pattern, line[len("replace:") :].strip()))
            pattern = None
    return rules


def _source(cell: dict) -> str:
    src = cell.get("source", "")
    return "".join(src) if isinstance(src, list) else src


def _text(value) -> str:
    return "".join(value) if isinstance(value, list) else str(value)


def cell_text(cell: dict, sanitizers=()) -> str:
    """A code cell's compared outputs as one text: streams merged by name, then the text data of
    results and displays, then errors as "ename: evalue" (tracebacks, images and metadata skipped)."""
    streams: dict[str, str] = {}
    parts: list[str] = []
    for out in cell.get("outputs", []):
        kind = out.get("output_type")
        if kind == "stream":
            streams[out.get("name", "stdout")] = streams.get(out.get("name", "stdout"), "") + _text(
                out["text"]
            )
        elif kind in ("execute_result", "display_data"):
            for key, value in sorted(out.get("data", {}).items()):
                if key not in SKIPPED_KEYS:
                    parts.append(f"[{key}]\n{_text(value)}")
        elif kind == "error":
            parts.append(f"[error] {out.get('ename', '')}: {out.get('evalue', '')}")
    text = "".join(f"[{name}]\n{t}" for name, t in streams.items()) + "\n".join(parts)
    for pattern, replacement in sanitizers:
        text = pattern.sub(replacement, text)
    return text


def code_cell_texts(nb: dict, sanitizers=()) -> list[str | None]:
    """Every code cell's compared text, in nbval's numbering; None for a cell nbval does not compare."""
    texts: list[str | None] = []
    for cell in nb.get("cells", []):
        if cell.get("cell_type") != "code":
            continue
        ignored = any(marker in _source(cell) for marker in IGNORE_MARKERS)
        texts.append(None if ignored else cell_text(cell, sanitizers))
    return texts


@dataclass(frozen=True)
class Difference:
    """One code cell whose text under one setting is not the stored text."""

    cell: int  # nbval's number: code cells from 0
    setting: str
    stored_line: str  # the first line that differs, as stored ("" if missing)
    fresh_line: str  # ... and as printed under the setting


def first_difference(a: str, b: str) -> tuple[str, str]:
    """The first line at which two texts differ: (line of a, line of b), "" where one ended."""
    la, lb = a.splitlines(), b.splitlines()
    for i in range(max(len(la), len(lb))):
        x, y = (la[i] if i < len(la) else ""), (lb[i] if i < len(lb) else "")
        if x != y:
            return x, y
    return "", ""


def compare(stored: dict, runs: dict[str, dict], sanitizers=()) -> list[Difference]:
    """The cells whose text differs from the stored notebook's under each setting of `runs`
    ({setting name: executed notebook}), sorted by cell, then in the order of `runs`."""
    ref = code_cell_texts(stored, sanitizers)
    found = []
    for setting, nb in runs.items():
        fresh = code_cell_texts(nb, sanitizers)
        if len(fresh) != len(ref):
            raise ValueError(f"{setting}: {len(fresh)} code cells, the stored notebook has {len(ref)}")
        for i, (r, f) in enumerate(zip(ref, fresh, strict=True)):
            if r is not None and f is not None and r != f:
                found.append(Difference(i, setting, *first_difference(r, f)))
    order = {s: k for k, s in enumerate(runs)}
    return sorted(found, key=lambda d: (d.cell, order[d.setting]))


def format_table(differences: list[Difference], width: int = 100) -> str:
    """The differences as a table: cell, setting, then the stored line and the fresh one."""

    def cut(s: str) -> str:
        return s if len(s) <= width else s[: width - 3] + "..."

    lines = [f"{'cell':>4s}  {'setting':14s}  first line that differs (stored / fresh)"]
    for d in differences:
        lines.append(f"{d.cell:4d}  {d.setting:14s}  - {cut(d.stored_line)}")
        lines.append(f"{'':4s}  {'':14s}  + {cut(d.fresh_line)}")
    return "\n".join(lines)


def execute(path: Path, env: dict[str, str], timeout: int):
    """The notebook executed in a fresh kernel with `env` added to this process's environment, in
    the notebook's folder (as execute_notebooks.py and nbval run it); errors are kept as outputs."""
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(
        nb,
        timeout=timeout,
        kernel_name="python3",
        resources={"metadata": {"path": str(path.parent)}},
        allow_errors=True,
        record_timing=False,
    )
    client.execute(env={**os.environ, "TQDM_DISABLE": "1", **env})
    return nb


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("notebooks", nargs="*", type=Path, help="notebooks to run")
    parser.add_argument(
        "--settings",
        default=",".join(DEFAULT_SETTINGS),
        help=f"comma-separated settings, or 'all' (default: {','.join(DEFAULT_SETTINGS)})",
    )
    parser.add_argument("--list-settings", action="store_true", help="print the settings and exit")
    parser.add_argument("--keep", type=Path, help="write the executed copies to this folder")
    parser.add_argument("--timeout", type=int, default=3600, help="seconds allowed per cell")
    args = parser.parse_args(argv)
    if args.list_settings:
        for name, (env, what) in SETTINGS.items():
            print(f"{name:14s} {what}\n{'':14s} {' '.join(f'{k}={v}' for k, v in env.items())}")
        return 0
    names = list(SETTINGS) if args.settings == "all" else [s.strip() for s in args.settings.split(",")]
    unknown = [s for s in names if s not in SETTINGS]
    if unknown or not args.notebooks:
        parser.error(f"unknown settings {unknown} (--list-settings)" if unknown else "no notebook given")
    for path in args.notebooks:
        if path.suffix != ".ipynb" or not path.is_file():
            parser.error(f"not a notebook: {path}")

    import nbformat

    sanitizers = load_sanitizers()
    found_any = False
    with tempfile.TemporaryDirectory() as tmp:
        out_dir = args.keep or Path(tmp)
        out_dir.mkdir(parents=True, exist_ok=True)
        for path in args.notebooks:
            stored = nbformat.read(path, as_version=4)
            runs = {}
            for name in names:
                print(f"{path}: executing as {name} ...", flush=True)
                try:
                    runs[name] = execute(path.resolve(), SETTINGS[name][0], args.timeout)
                except Exception as exc:  # a cell timed out, the kernel died: no notebook to compare
                    found_any = True
                    first = str(exc).strip().splitlines()[:1]
                    print(f"{path}: execution as {name} FAILED: {type(exc).__name__} {' '.join(first)}")
                    continue
                nbformat.write(runs[name], out_dir / f"{path.stem}.{name}.ipynb")
            differences = compare(stored, runs, sanitizers)
            if differences:
                found_any = True
                cells = sorted({d.cell for d in differences})
                print(f"{path}: {len(cells)} cell(s) differ from the stored outputs: {cells}")
                print(format_table(differences))
            elif runs:
                print(f"{path}: every setting printed the stored outputs ({', '.join(runs)})")
    return 1 if found_any else 0


if __name__ == "__main__":
    sys.exit(main())

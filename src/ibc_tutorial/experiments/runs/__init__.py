"""What every study's folder shares, so that neither study imports the other.

- ``files``: reading and writing its files, each checked as it is read (``write_json``,
  ``read_json_dict``, ``write_npz``, ``read_npz``, ``read_torch_file``, ``read_run_file``);
- ``provenance``: the machine, the commit, and ``Provenance``, every invocation of a resumable command
  with its heartbeat, written to ``provenance.json`` and ``PROVENANCE.md``;
- ``folder``: the lifecycle of a study's folder (``StudyFolder``: its layout, checks, ``--force``,
  resuming, ``results.json`` after every run, loading), ``run_dir``, ``DATA``, ``run_missing``,
  ``run_missing_recorded`` and ``read_driver_files``.

Everything is importable from here: ``from ibc_tutorial.experiments.runs import StudyFolder``.
"""

from ibc_tutorial.experiments.runs.files import (
    PROVENANCE,
    PROVENANCE_MD,
    RESULTS,
    read_json,
    read_json_dict,
    read_npz,
    read_run_file,
    read_torch_file,
    write_json,
    write_npz,
)
from ibc_tutorial.experiments.runs.folder import (
    DATA,
    Run,
    StudyFolder,
    check_folder_entries,
    clear_entries,
    differing,
    read_driver_files,
    read_folder,
    run_dir,
    run_missing,
    run_missing_recorded,
)
from ibc_tutorial.experiments.runs.provenance import (
    CPU_ENVIRONMENT,
    HEARTBEAT_S,
    Provenance,
    add_note,
    begin_invocation,
    git_commit,
    invocations_of,
    machine,
    now,
)

__all__ = [
    "CPU_ENVIRONMENT",
    "DATA",
    "HEARTBEAT_S",
    "PROVENANCE",
    "PROVENANCE_MD",
    "RESULTS",
    "Provenance",
    "add_note",
    "Run",
    "StudyFolder",
    "begin_invocation",
    "check_folder_entries",
    "clear_entries",
    "differing",
    "git_commit",
    "invocations_of",
    "machine",
    "now",
    "read_folder",
    "read_json",
    "read_json_dict",
    "read_npz",
    "read_run_file",
    "read_torch_file",
    "run_dir",
    "run_missing",
    "run_missing_recorded",
    "read_driver_files",
    "write_json",
    "write_npz",
]

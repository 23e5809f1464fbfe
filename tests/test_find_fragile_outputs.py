"""tools/find_fragile_outputs.py: the comparison of executed notebooks with the stored one (no
notebook is executed here: the notebooks are small dicts in nbformat's shape)."""

import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import find_fragile_outputs as ffo  # noqa: E402


def code(source, *outputs):
    return {"cell_type": "code", "source": source, "outputs": list(outputs), "metadata": {}}


def stdout(text):
    return {"output_type": "stream", "name": "stdout", "text": text}


def result(text, png=None):
    data = {"text/plain": text}
    if png is not None:
        data["image/png"] = png
    return {"output_type": "execute_result", "data": data, "metadata": {}, "execution_count": 1}


def notebook(*cells):
    return {"cells": [{"cell_type": "markdown", "source": "# title", "metadata": {}}, *cells]}


def stored():
    return notebook(
        code("print(x)", stdout("whiteness 6.1\n")),
        code("# NBVAL_IGNORE_OUTPUT\nprint(t)", stdout("took 3 s\n")),
        code("f", result("<object at 0x7f3a2b1c9d00>", png="AAAA")),
        code("print(n)", stdout("seeds: "), stdout("4 of 5\n")),
    )


def test_identical_runs_have_no_difference():
    runs = {"native-1": stored(), "older-cpu": stored()}
    assert ffo.compare(stored(), runs, ffo.load_sanitizers()) == []


def test_a_changed_digit_is_found_under_its_setting_only():
    fresh = stored()
    fresh["cells"][1]["outputs"] = [stdout("whiteness 6.0\n")]
    found = ffo.compare(stored(), {"native-1": stored(), "older-cpu": fresh})
    assert found == [ffo.Difference(0, "older-cpu", "whiteness 6.1", "whiteness 6.0")]
    table = ffo.format_table(found)
    assert "older-cpu" in table and "- whiteness 6.1" in table and "+ whiteness 6.0" in table


def test_ignored_cells_images_split_streams_and_sanitized_addresses_are_not_differences():
    fresh = stored()
    fresh["cells"][2]["outputs"] = [stdout("took 9 s\n")]  # NBVAL_IGNORE_OUTPUT
    fresh["cells"][3]["outputs"] = [result("<object at 0x55d0aa11bb22>", png="BBBB")]  # address, image
    fresh["cells"][4]["outputs"] = [stdout("seeds: 4 of 5\n")]  # one stream instead of two
    assert ffo.compare(stored(), {"avx2": fresh}, ffo.load_sanitizers()) == []
    # without the sanitizer the address differs
    assert [d.cell for d in ffo.compare(stored(), {"avx2": fresh})] == [2]


def test_an_error_counts_as_a_difference_and_cells_are_numbered_as_nbval_does():
    fresh = stored()
    fresh["cells"][4]["outputs"] = [
        stdout("seeds: 3 of 5\n"),
        {"output_type": "error", "ename": "AssertionError", "evalue": "", "traceback": ["..."]},
    ]
    (d,) = ffo.compare(stored(), {"older-cpu": fresh})
    assert d.cell == 3 and d.stored_line == "seeds: 4 of 5" and d.fresh_line == "seeds: 3 of 5"
    only_error = stored()
    only_error["cells"][4]["outputs"].append(
        {"output_type": "error", "ename": "AssertionError", "evalue": ""}
    )
    (d,) = ffo.compare(stored(), {"older-cpu": only_error})
    assert d.stored_line == "" and d.fresh_line.startswith("[error] AssertionError")


def test_a_notebook_with_other_cells_is_refused():
    fresh = stored()
    fresh["cells"].append(code("print(1)", stdout("1\n")))
    with pytest.raises(ValueError, match="code cells"):
        ffo.compare(stored(), {"native-1": fresh})


def test_sanitizers_are_read_from_the_nbval_file():
    rules = ffo.load_sanitizers()
    assert any(p.pattern == re.compile(r"0x[0-9a-fA-F]{6,}").pattern and r == "0xADDRESS" for p, r in rules)


def test_settings_are_known_and_the_older_cpu_is_cis():
    assert set(ffo.DEFAULT_SETTINGS) <= set(ffo.SETTINGS)
    env = ffo.SETTINGS["older-cpu"][0]
    assert env["ATEN_CPU_CAPABILITY"] == "default" and env["MKL_ENABLE_INSTRUCTIONS"] == "SSE4_2"
    assert env["OMP_NUM_THREADS"] == "1" and env["IBC_TUTORIAL_WORKERS"] == "1"

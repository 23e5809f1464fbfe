"""``tools/build_site.py``'s API page: what it asks Sphinx to describe (the build itself runs in CI)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import build_site  # noqa: E402


def test_a_package_leaves_a_member_named_like_a_documented_submodule_to_that_module():
    """``driving`` re-exports the function ``rollout`` of its module ``driving.rollout``: were both on the
    page, Sphinx would describe ``ibc_tutorial.driving.rollout`` twice and the strict build would fail."""
    modules = ["ibc_tutorial", "ibc_tutorial.driving", "ibc_tutorial.driving.rollout", "ibc_tutorial.stats"]
    assert build_site._shadowed("ibc_tutorial.driving", modules) == ["rollout"]
    assert build_site._shadowed("ibc_tutorial", modules) == ["driving", "stats"]  # not the grandchild
    assert build_site._shadowed("ibc_tutorial.stats", modules) == []
    page = build_site.library_page(modules, Path(build_site.ROOT))
    assert ".. automodule:: ibc_tutorial.driving\n   :exclude-members: rollout\n" in page
    assert ".. automodule:: ibc_tutorial.stats\n```" in page

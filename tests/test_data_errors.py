"""Every error about the article's missing data names BEYOND_DATA, the one setting that points
every command at it, and nothing the package ships cites SPEC.md, which is not in it."""

from __future__ import annotations

from pathlib import Path

import pytest

import beyond_self.cognition.paths as paths
from beyond_self.cli import main
from beyond_self.core.errors import InputError

PACKAGE = Path(paths.__file__).resolve().parent.parent


@pytest.fixture
def no_data(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """A machine without the article's data: no BEYOND_DATA, nothing beside the checkout."""
    monkeypatch.delenv("BEYOND_DATA", raising=False)
    monkeypatch.setattr(paths, "BESIDE_CHECKOUT", tmp_path / "no-shared-data")


@pytest.mark.parametrize(
    "data",
    [None, "absent-folder", "empty-folder"],
    ids=["no-data-anywhere", "--data-absent", "--data-lacks-files"],
)
def test_reproduce_without_data_names_beyond_data(
    data: str | None, no_data: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "empty-folder").mkdir()
    argv = ["reproduce", "-o", str(tmp_path / "out")]
    if data is not None:
        argv += ["--data", str(tmp_path / data)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "BEYOND_DATA" in err, err


def test_the_librarys_data_errors_name_beyond_data(
    no_data: None, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    with pytest.raises(InputError, match="BEYOND_DATA"):
        paths.require_shared_data("salvi2012/networkDefinition.txt")
    with pytest.raises(InputError, match="BEYOND_DATA"):
        paths.data_set("human_data")
    (tmp_path / "data" / "salvi2012").mkdir(parents=True)
    monkeypatch.setenv("BEYOND_DATA", str(tmp_path / "data"))
    with pytest.raises(InputError, match="BEYOND_DATA"):
        paths.require_shared_data("salvi2012/networkDefinition.txt")


def test_nothing_shipped_cites_spec_md() -> None:
    cited = [
        str(p.relative_to(PACKAGE))
        for p in PACKAGE.rglob("*")
        if p.suffix in (".py", ".md") and "SPEC.md" in p.read_text(encoding="utf-8")
    ]
    assert cited == []

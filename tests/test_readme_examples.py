"""Every `aacmm` example line of the README's code blocks runs (outputs redirected to a temp folder)."""
from __future__ import annotations

import re
import shlex

import pytest

from arm_model.cli import main
from conftest import ROOT


def readme_commands() -> list[list[str]]:
    text = (ROOT / "README.md").read_text()
    out = []
    for block in re.findall(r"```\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            line = line.split("#", 1)[0].strip()
            if line.startswith(".venv/bin/aacmm "):
                out.append(shlex.split(line)[1:])
    return out


def test_readme_has_examples():
    assert len(readme_commands()) >= 2


@pytest.mark.parametrize("argv", readme_commands(), ids=lambda a: " ".join(a[:2]))
def test_readme_example_runs(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    argv = [str(tmp_path / a.split("/", 1)[1]) if a.startswith("out/") else a for a in argv]
    if argv == ["--help"]:
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 0 and "close-loop" in capsys.readouterr().out
        return
    assert main(argv) == 0

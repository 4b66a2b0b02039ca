"""The README's Python example runs as written and its audits pass the issue's tolerances."""
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[2] / "README.md"


@pytest.mark.slow
def test_readme_synthesis_example_runs(capsys):
    block = re.search(r"## Synthesis from Python.*?```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert block, "README lost its Python example"
    ns: dict = {}
    exec(compile(block.group(1), "README.md", "exec"), ns)
    out = capsys.readouterr().out
    assert out.count("Audit(") == 2
    aud = ns["syn"].audit  # the run's
    assert ns["syn"].result.success
    assert aud.footstep_error_max <= 1e-3 and aud.penetration_max <= 1e-3 and aud.root_residual_rel <= 5e-3
    assert aud.dense_residual_max <= 0.05  # the equations of motion at every 120 Hz frame (issue #15)


def test_readme_is_a_user_document():
    """README ≤ 200 lines, no line over 300 characters, two quick-start commands, links inside the repo."""
    text = README.read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= 200, len(lines)
    assert max(len(line) for line in lines) <= 300
    quick, inside = [], False  # the lines ../shared/tools/fresh-check runs: 4-space indented under "## Quick start"
    for line in lines:
        if line.startswith("## "):
            inside = line.lower().startswith(("## quick start", "## quickstart"))
        elif inside and line.startswith("    ") and not line.startswith("     "):
            quick.append(line[4:])
    assert len(quick) == 2 and quick[0].startswith("python -m pip install -e . && compose run walk"), quick
    links = re.findall(r"\]\(([^)]+)\)", text)
    assert links, "README lost its links"
    for link in links:
        assert not link.startswith(("..", "/")), link
        if not link.startswith(("http://", "https://")):
            assert (README.parent / link.split("#")[0]).exists(), link

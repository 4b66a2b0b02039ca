"""The README's Python example runs as written and its audits pass the issue's tolerances."""
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


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
    assert aud.footstep_error_max <= 1e-3 and aud.penetration_max <= 1e-3 and aud.root_residual_rel <= 1e-3

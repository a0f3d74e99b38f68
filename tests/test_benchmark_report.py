"""A benchmark's report says which code it measured: ``benchmarks/common.py`` puts its own checkout first on
``sys.path`` (a virtual environment's editable install may point at another checkout) and records the commit, with
"+changes" when tracked files differ from it."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def git(*args: str, cwd: Path) -> str:
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=True).stdout.strip()


def write_a_report(checkout: Path, out: Path) -> dict:
    """Run a one-line benchmark of ``checkout`` that imports ``common`` and then the project's ``policies``, from
    another directory (as a script's own folder, not the checkout, is what Python puts on the path)."""
    script = (f"import sys; sys.path.insert(0, {str(checkout / 'benchmarks')!r}); import common, policies; "
              f"common.write_report({str(out)!r}, {{'policies': policies.__file__}})")
    subprocess.run([sys.executable, "-c", script], cwd=out.parent, capture_output=True, text=True, check=True)
    return json.loads(out.read_text())


def test_a_report_names_the_commit_and_the_checkout_it_measured(tmp_path):
    checkout = tmp_path / "checkout"  # a checkout of its own: benchmarks/common.py and an empty policies package
    for name in ("benchmarks/common.py", "policies/__init__.py"):
        (checkout / name).parent.mkdir(parents=True, exist_ok=True)
        (checkout / name).write_text((ROOT / name).read_text() if name.startswith("benchmarks") else "")
    git("init", "--quiet", cwd=checkout)
    git("add", ".", cwd=checkout)
    git("-c", "user.name=t", "-c", "user.email=t@example.com", "commit", "--quiet", "-m", "x", cwd=checkout)
    commit = git("rev-parse", "--short", "HEAD", cwd=checkout)

    report = write_a_report(checkout, tmp_path / "report.json")
    # this interpreter's own install of the project is elsewhere: the benchmark imported the checkout beside it
    assert Path(report["policies"]).resolve() == (checkout / "policies" / "__init__.py").resolve()
    assert report["code"] == commit
    assert report["command"].startswith("python -c")
    assert not (tmp_path / "report.json.tmp").exists()

    (checkout / "policies" / "__init__.py").write_text("# changed\n")
    assert write_a_report(checkout, tmp_path / "report.json")["code"] == commit + "+changes"

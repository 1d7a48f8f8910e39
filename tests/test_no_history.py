"""The tracked files read as a manual, not as a development log: no dates, commit hashes, "session" words or
tracker numbers outside CHANGELOG.md (where what changed for users is recorded by version)."""

import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
EXEMPT = {"CHANGELOG.md", "tests/test_no_history.py"}
TEXT_SUFFIXES = {".py", ".md", ".toml", ".cff", ".yml", ".yaml", ".ipynb", ".txt", ".cfg", ".json", ""}
PATTERNS = {
    "session": re.compile(r"\bsessions?\b", re.IGNORECASE),
    "commit hash": re.compile(r"\b(?:at|commit|commits|in|of|clone of|hash)\s+`?[0-9a-f]{7,40}\b`?", re.IGNORECASE),
    "issue number": re.compile(r"\bissues?[ -]#?\d+", re.IGNORECASE),
    "date": re.compile(r"\b(?:19|20)\d\d-(?:0[1-9]|1[0-2])-(?:0[1-9]|[12]\d|3[01])\b"),
    "probe": re.compile(r"\bprob(?:e|es|ed|ing)\b", re.IGNORECASE),
    "a file users do not have": re.compile(r"PHYSICS\.md"),
}
# Generated from results files, or results files themselves, whose date says when the numbers were measured.
DATED = {"docs/benchmarks.md", "docs/results.md"}
DATED_FOLDERS = ("calibration/results/", "benchmarks/results/")
# Code, not history: pytest's fixture scope is called "session".
ALLOWED = re.compile(r"scope=[\"']session[\"']")


def _tracked():
    try:
        names = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    for name in names.splitlines():
        path = REPO / name
        if name in EXEMPT or path.suffix not in TEXT_SUFFIXES or not path.is_file() or path.is_symlink():
            continue
        if path.suffix == ".json" and path.stat().st_size > 200_000:
            continue
        yield name, path


def test_no_development_history_in_tracked_files():
    hits = []
    for name, path in _tracked():
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            line = ALLOWED.sub("", line)
            for what, pattern in PATTERNS.items():
                if pattern.search(line) and not (what == "date" and (name in DATED or name.startswith(DATED_FOLDERS))):
                    hits.append(f"{name}:{number}: {what}: {line.strip()[:120]}")
    assert not hits, f"{len(hits)} lines of development history:\n" + "\n".join(hits)

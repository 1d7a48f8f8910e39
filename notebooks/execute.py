"""Execute the tutorials and store them with their outputs, so that GitHub and the documentation site show them
without running them.

    python notebooks/execute.py [--ci] [NAMES...]

Each notebook named (by file stem; default: every notebook that ``sizes.toml`` lists) runs top to bottom in a
fresh kernel started in this folder and is written back in place with its outputs. ``--ci`` runs the reduced
sizes of ``sizes.toml`` (``GROWJAX_QUICK=1``), and the notebook's first markdown cell then says so, naming each
reduced size beside the one its code sets. Execution counts, outputs and figures are stored; timing metadata
and the kernel's version are not, so that a re-run gives a small diff.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
import tomllib
from pathlib import Path

import nbformat
from nbclient import NotebookClient

FOLDER = Path(__file__).resolve().parent
SIZES = FOLDER / "sizes.toml"
NOTICE = "> **Outputs shown at reduced sizes**"  # the first words of the notice in the first markdown cell


def sizes(path: Path = SIZES) -> dict[str, dict[str, dict]]:
    """``{notebook stem: {"full": {name: value}, "ci": {name: value}}}`` as ``sizes.toml`` sets them.

    Raises:
        ValueError: a notebook without both tables, or whose two tables set different names.
    """
    table = tomllib.loads(path.read_text())
    for name, entry in table.items():
        if set(entry) != {"full", "ci"}:
            raise ValueError(
                f"{path.name}: [{name}] needs a [{name}.full] and a [{name}.ci] table, has {sorted(entry)}"
            )
        if set(entry["full"]) != set(entry["ci"]):
            raise ValueError(f"{path.name}: [{name}.full] and [{name}.ci] set different names")
    return table


def notice(entry: dict[str, dict]) -> str:
    """The markdown paragraph that says a notebook's outputs were made at its reduced sizes."""
    changed = [
        f"`{k} = {v!r}` (as written: `{entry['full'][k]!r}`)" for k, v in entry["ci"].items() if v != entry["full"][k]
    ]
    return (
        f"{NOTICE} to keep the documentation's build short: "
        + ", ".join(changed)
        + ". The code as written runs the full sizes; its numbers and figures will differ from those shown."
    )


def with_notice(markdown: str, text: str | None) -> str:
    """``markdown`` with its reduced-sizes notice replaced by ``text`` (None: removed)."""
    kept = [p for p in re.split(r"\n\n+", markdown.strip()) if not p.startswith(NOTICE)]
    return "\n\n".join(kept + ([text] if text else []))


def execute(path: Path, *, ci: bool, cwd: Path | None = None, timeout: int = 3600) -> nbformat.NotebookNode:
    """Run the notebook at ``path`` top to bottom in a kernel started in ``cwd`` (default: its folder).

    Args:
        path: the notebook.
        ci: run the reduced sizes (``GROWJAX_QUICK=1``) rather than the full ones.
        cwd: the kernel's working folder; it must hold ``sizes.toml``, and the notebook's figures are written
            under it.
        timeout: s that one cell may run.

    Returns:
        The executed notebook (the file is not written).

    Raises:
        nbclient.exceptions.CellExecutionError: a cell raised; the message holds the cell and its traceback.
    """
    nb = nbformat.read(path, as_version=4)
    env = dict(os.environ, GROWJAX_QUICK="1" if ci else "0")
    client = NotebookClient(
        nb,
        timeout=timeout,
        kernel_name="python3",
        record_timing=False,
        resources={"metadata": {"path": str(cwd or path.parent)}},
    )
    client.execute(env=env)
    return nb


def store(nb: nbformat.NotebookNode, path: Path, *, ci: bool, entry: dict[str, dict]) -> None:
    """Write the executed ``nb`` to ``path``: the reduced-sizes notice set or removed, metadata kept small (a
    notebook whose reduced sizes are its full ones counts as run at full size)."""
    reduced = ci and entry["ci"] != entry["full"]
    first = next(c for c in nb.cells if c.cell_type == "markdown")
    first.source = with_notice(first.source, notice(entry) if reduced else None)
    nb.metadata.pop("widgets", None)
    nb.metadata["language_info"] = {"name": "python"}
    nb.metadata["growjax"] = {"sizes": "ci" if reduced else "full"}
    for cell in nb.cells:
        cell.metadata.pop("execution", None)
    nbformat.write(nb, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="notebooks by stem (default: all that sizes.toml lists)")
    parser.add_argument("--ci", action="store_true", help="the reduced sizes (GROWJAX_QUICK=1)")
    parser.add_argument("--timeout", type=int, default=3600, help="s one cell may run (default 3600)")
    args = parser.parse_args(argv)
    table = sizes()
    unknown = [n for n in args.names if n not in table or not (FOLDER / f"{n}.ipynb").is_file()]
    if unknown:
        parser.error(f"not a notebook that sizes.toml lists: {', '.join(unknown)}")
    for name in args.names or list(table):
        path = FOLDER / f"{name}.ipynb"
        start = time.perf_counter()
        nb = execute(path, ci=args.ci, timeout=args.timeout)
        store(nb, path, ci=args.ci, entry=table[name])
        print(f"{name}: {time.perf_counter() - start:.0f} s at the {'ci' if args.ci else 'full'} sizes", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

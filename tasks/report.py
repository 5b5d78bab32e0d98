"""Summarise `vlr task` runs: `python -m vlr.tasks.report DIR [DIR ...]` reads each DIR/result.json
and prints, per task, the mean and SD over runs of each headline error and the successes,
as the Markdown rows of docs/TASKS.md (`vlr.task_report`, which `vlr task --seeds` also
writes as OUT/summary.md)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from vlr.task_report import HEADLINES, summarize

__all__ = ["HEADLINES", "summarize", "main"]


def main(argv: list[str] | None = None) -> int:
    dirs = [Path(a) for a in (argv if argv is not None else sys.argv[1:])]
    results = []
    for d in dirs:
        f = d / "result.json" if d.is_dir() else d
        if f.is_file() and f.suffix == ".json":
            results.append(json.loads(f.read_text()))
    if not results:
        print("no result.json found", file=sys.stderr)
        return 2
    print("| task | seeds | mean +- SD over runs (per run) | successes |")
    print("|---|---|---|---|")
    print("\n".join(summarize(results)))
    return 0


if __name__ == "__main__":
    sys.exit(main())

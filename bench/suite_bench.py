"""make bench (part): the wall time of ``make test`` itself (the fast suite, a worker per core), beside issue 24's
goal of under 4 minutes on 2 cores, with pytest's count: the time of a suite that failed says nothing."""

from __future__ import annotations

import os
import re
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GOAL = 240.0  # [s], on 2 cores


def main() -> None:
    started = time.perf_counter()
    done = subprocess.run(
        ["make", "--no-print-directory", "test"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - started
    lines = done.stdout.strip().splitlines()
    summary = re.sub(r"=+", "", lines[-1]).strip() if lines else f"no output (exit code {done.returncode})"
    print(f"make test: {wall:.0f} s wall on {os.cpu_count()} cores, {summary} (goal < {GOAL:.0f} s on 2 cores)")


if __name__ == "__main__":
    main()

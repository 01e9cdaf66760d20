"""Re-make every table of docs/results.md: run the commands of its ```bash blocks in the order the page
gives them, from the repository root, each command once (a sweep run again into its folder only trains
the runs it lacks, and the report scripts only read). The page is the list, so the commands run are the
ones the page quotes. On 2 CPU cores the whole page takes days; ``--start K`` goes on from command K.

    python scripts/make_tables.py --dry-run     # list the commands, numbered
    python scripts/make_tables.py               # run them all (``make tables``)
    python scripts/make_tables.py --start 12    # go on from command 12
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results.md"
_FENCE = re.compile(r"^```bash\n(.*?)^```", re.S | re.M)


def commands(path: Path = RESULTS) -> list[str]:
    """The shell commands of the page's ```bash blocks, in order, each once."""
    seen: dict[str, None] = {}
    for block in _FENCE.findall(path.read_text(encoding="utf-8")):
        for line in block.splitlines():
            line = line.strip()
            if line and not line.startswith("#"):
                seen.setdefault(line, None)
    return list(seen)


def shell_line(command: str) -> str:
    """``command`` with its leading ``python`` replaced by this interpreter (``hubsgo`` is found on the
    PATH that :func:`main` puts this interpreter's folder at the front of)."""
    if command.startswith("python "):
        return shlex.quote(sys.executable) + command[len("python"):]
    return command


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dry-run", action="store_true", help="print the commands, numbered, and run nothing")
    p.add_argument("--start", type=int, default=1, metavar="K", help="begin with command K (1-based)")
    args = p.parse_args(argv)
    todo = commands()
    if not 1 <= args.start <= len(todo):
        print(f"make_tables: --start must lie between 1 and {len(todo)}, got {args.start}", file=sys.stderr)
        return 2
    if args.dry_run:
        for i, cmd in enumerate(todo, 1):
            print(f"{i:>3}  {cmd}")
        return 0
    env = dict(os.environ, PATH=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]))
    for i, cmd in enumerate(todo[args.start - 1:], args.start):
        print(f"[{i}/{len(todo)}] {cmd}", flush=True)
        rc = subprocess.run(["bash", "-c", shell_line(cmd)], cwd=ROOT, env=env).returncode
        if rc != 0:
            print(f"make_tables: command {i} exited with {rc}; fix it and go on with --start {i}", file=sys.stderr)
            return rc
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""scripts/make_tables.py and the commands of docs/results.md: every command the page quotes names files
that exist and flags its program takes, so a deleted sweep, script or option cannot linger in the docs,
and every section with a table says how to re-make it."""

from __future__ import annotations

import re
import shlex
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import make_tables  # noqa: E402  (a script module, not a package)

RESULTS = ROOT / "docs" / "results.md"
_PATH = re.compile(r"^(?:sweeps|scripts|benchmarks|models|envs)/\S+$")


def _words(command: str) -> list[str]:
    return shlex.split(command.replace("$(", "").replace(")", ""))


def test_the_page_quotes_commands_and_each_runs_once():
    todo = make_tables.commands(RESULTS)
    assert len(todo) >= 20
    assert len(todo) == len(set(todo))
    assert all(c.split()[0] in ("hubsgo", "python") for c in todo), [c for c in todo if c.split()[0] not in ("hubsgo", "python")]


@pytest.mark.parametrize("command", make_tables.commands(RESULTS))
def test_every_file_a_command_names_exists(command):
    paths = [w for w in _words(command) if _PATH.match(w)]
    if command.startswith("hubsgo sweep") or command.startswith("python "):
        assert paths, f"no repository file named in: {command}"
    for p in paths:
        matches = list(ROOT.glob(p.replace("{task}", "*")))
        assert matches, f"{p} (quoted in docs/results.md: {command}) is not in the repository"


@pytest.mark.parametrize("command", [c for c in make_tables.commands(RESULTS) if c.startswith("hubsgo ")])
def test_every_hubsgo_command_parses(command):
    from hubsgo_ppl.cli import build_parser

    try:
        build_parser().parse_args(_words(command)[1:])
    except (SystemExit, Exception) as exc:     # argparse's exit, or the CLI's one-line UsageError
        pytest.fail(f"hubsgo refuses the arguments of `{command}`: {exc}")


@pytest.mark.parametrize("command", [c for c in make_tables.commands(RESULTS) if c.startswith("python ")])
def test_every_flag_of_a_script_command_is_one_the_script_defines(command):
    words = _words(command)
    script = ROOT / words[1]
    source = script.read_text(encoding="utf-8")
    if "measure_common" in source:          # the options shared by the measure_* scripts
        source += (ROOT / "scripts" / "measure_common.py").read_text(encoding="utf-8")
    for flag in (w for w in words[2:] if w.startswith("--")):
        assert f'"{flag}"' in source, f"{script.name} defines no option {flag} (docs/results.md: {command})"


def test_every_section_with_a_table_gives_its_commands():
    text = RESULTS.read_text(encoding="utf-8")
    sections = re.split(r"^## ", text, flags=re.M)[1:]
    for section in sections:
        title = section.splitlines()[0]
        if title.startswith("What we tried") or "\n|---" not in section:
            continue
        assert make_tables._FENCE.search(section), f"section '{title}' has a table and no ```bash block"


def test_the_page_stays_a_reference_of_at_most_600_lines():
    assert len(RESULTS.read_text(encoding="utf-8").splitlines()) <= 600


def test_a_python_command_runs_with_this_interpreter():
    line = make_tables.shell_line("python scripts/critic_report.py runs/x --no-eval")
    assert line.startswith(shlex.quote(sys.executable) + " scripts/critic_report.py")
    assert make_tables.shell_line("hubsgo sweep sweeps/quick.yaml") == "hubsgo sweep sweeps/quick.yaml"


def test_a_start_outside_the_list_is_refused(capsys):
    assert make_tables.main(["--start", "0"]) == 2
    assert "--start must lie between 1 and" in capsys.readouterr().err

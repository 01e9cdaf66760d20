"""The README is a quickstart that works: its Python snippets run as written (with the budget they
state), its maze and spec pass `hubsgo tasks`, its links point at files, it stays short, and neither it
nor docs/ cites commits."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
# a commit hash: 7-40 hex digits holding both a digit and a letter (numbers and words are not hashes)
HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")


def blocks(lang: str, path: Path = README) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", path.read_text(encoding="utf-8"), flags=re.S | re.M)


def test_the_readme_is_a_quickstart_of_at_most_1000_words():
    assert len(README.read_text(encoding="utf-8").split()) <= 1000


def test_the_python_training_snippet_runs_and_writes_g_star(tmp_path, monkeypatch, capsys):
    snippet = next(b for b in blocks("python") if "train(" in b)
    assert len(snippet.strip().splitlines()) <= 15
    assert "steps=2000" in snippet      # the budget the README states, small enough for a test
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(snippet, "README.md", "exec"), scope)
    assert scope["summary"]["finished"] is True
    assert scope["summary"]["env_steps"] >= 2000
    g_star = json.loads((tmp_path / "runs" / "py-keydoor" / "subgoals.json").read_text())
    assert g_star["ranking"][0]["subgoals"] == scope["g_star"][0]["subgoals"]
    assert str(scope["g_star"][0]["subgoals"]) in capsys.readouterr().out
    import csv                      # the user's callback saw the episodes metrics.csv logs
    rows = list(csv.DictReader(open(tmp_path / "runs" / "py-keydoor" / "metrics.csv")))
    wins = [int(float(r["env_steps"])) for r in rows if int(float(r["success"])) == 1]
    assert getattr(scope["first"], "step", None) == (wins[0] if wins else None)


def test_the_critic_snippet_learns_the_route_of_its_successes(tmp_path, monkeypatch):
    snippet = next(b for b in blocks("python") if "SubgoalCritic" in b)
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(snippet, "README.md", "exec"), scope)
    top = scope["critic"].ranking(num_samples=10_000)[0]
    assert top["subgoals"] == ["blue_key", "blue_door", "goal"]
    assert top["prob"] > 0.5
    assert scope["critic"].marginals()[0] < 0.2         # the yellow key, which no success took


def test_the_readme_maze_and_spec_pass_hubsgo_tasks(tmp_path, capsys):
    from hubsgo_ppl.cli import main

    layout, = blocks("text")
    catalogue = next(b for b in blocks("yaml") if "family:" in b)
    spec = next(b for b in blocks("yaml") if "edges:" in b)
    assert len(layout.splitlines()) + len(catalogue.splitlines()) <= 10
    mazes = tmp_path / "mazes"
    mazes.mkdir()
    (mazes / "tiny.txt").write_text(layout)
    (mazes / "tiny.yaml").write_text(catalogue)
    (mazes / "tiny_spec.yaml").write_text(spec)
    assert main(["tasks", str(mazes / "tiny.yaml"), "--model", str(mazes / "tiny_spec.yaml")]) == 0
    out = capsys.readouterr().out
    assert "the goal and every sub-goal can be reached" in out
    assert "valid for this task" in out


def test_every_relative_link_of_the_readme_and_docs_exists():
    for page in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", page.read_text(encoding="utf-8")):
            if not target.startswith(("http://", "https://")):
                assert (page.parent / target).exists(), f"{page.relative_to(ROOT)} links to a missing {target}"


@pytest.mark.parametrize("page", [README, *sorted((ROOT / "docs").glob("*.md")), ROOT / "notebooks" / "README.md",
                                  *sorted((ROOT / "sweeps").glob("*.yaml"))],
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_no_page_cites_a_commit(page):
    text = page.read_text(encoding="utf-8")
    assert not HASH.findall(text)
    assert "code version" not in text


def test_the_td_critic_snippet_of_docs_critic_puts_the_two_routes_on_top(tmp_path, monkeypatch):
    snippet, = blocks("python", ROOT / "docs" / "critic.md")
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(snippet, "docs/critic.md", "exec"), scope)
    top = [frozenset(r["subgoals"]) for r in scope["critic"].ranking(num_samples=10_000, top_k=2)]
    assert set(top) == {frozenset({"yellow_key", "yellow_door", "goal"}), frozenset({"blue_key", "blue_door", "goal"})}

"""scripts/review_suggestions.py: review and revise copies of a sweep's finished runs, and count the
routes G* names before and after, on a run whose critic has no edges and whose successes took one route."""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
import review_suggestions  # noqa: E402  (a script module, not a package)

import torch  # noqa: E402

from hubsgo_ppl.experiments.io import load_checkpoint, save_torch, write_json  # noqa: E402
from hubsgo_ppl.experiments.run import RunConfig, load_run, subgoal_table, train  # noqa: E402

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]


def _settled_run_without_edges(run: Path) -> None:
    """A finished tiny KeyDoor run without edges, its critic and recent successes set by hand: every one
    of 20 successes took the blue route, and the agent counts as settled."""
    train(RunConfig(task="keydoor", agent="hubsgo", graph="independent", steps=300, seed=1, overrides=TINY), run,
          progress=False)
    path = run / "checkpoint.pt"
    ckpt = load_checkpoint(path)
    names = ckpt["agent"]["filter"]["critic"]["names"]
    blue = [[1.0 if n in ("blue_key", "blue_door", "goal") else 0.0 for n in names]] * 20
    ckpt["agent"]["filter"]["outcomes"] = torch.tensor(blue)
    ckpt["agent"]["filter"]["critic"]["theta"][:] = -2.0
    ckpt["agent"]["filter"]["critic"]["num_updates"] = 1
    ckpt["agent"]["settled_step"] = int(ckpt["env_steps"])
    save_torch(path, ckpt)
    _, env, agent, _ = load_run(run)
    env.close()
    write_json(run / "subgoals.json", subgoal_table(agent.g_star_critic(), list(names)))


def test_a_run_without_edges_names_the_route_after_the_suggested_revision(tmp_path, capsys):
    run = tmp_path / "sweep" / "keydoor" / "hubsgo-independent" / "seed0"
    _settled_run_without_edges(run)
    before = json.loads((run / "subgoals.json").read_text())["ranking"][0]["subgoals"]
    assert before == []
    sys.argv = ["review_suggestions.py", str(tmp_path / "sweep")]
    review_suggestions.main()
    out = capsys.readouterr().out
    assert "| keydoor (hubsgo-independent) | 1 | 0/1 | 1/1 |" in out, out
    assert "links suggested blue_key--goal, blue_door--goal; after {blue_door, blue_key, goal}" in out
    copy = tmp_path / "sweep_reviewed" / "keydoor" / "hubsgo-independent" / "seed0"
    assert (copy / "revisions.csv").exists() and not (run / "revisions.csv").exists()   # the sweep's run untouched
    # a second pass reads the revised copy instead of revising it again
    review_suggestions.main()
    assert "| keydoor (hubsgo-independent) | 1 | 0/1 | 1/1 |" in capsys.readouterr().out
    assert len((copy / "revisions.csv").read_text().splitlines()) == 2

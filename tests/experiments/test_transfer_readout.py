"""G* of a run whose critic came by ``--init-from`` and never updated is the source run's critic, and the
line under the G* table says so instead of calling it the spec's prior."""

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments.run import RunConfig, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]


def _last_line(run, capsys):
    capsys.readouterr()
    assert main(["subgoals", str(run)]) == 0
    return capsys.readouterr().out.strip().splitlines()[-1]


def test_a_transferred_critic_that_never_updated_is_named_as_the_source_runs(tmp_path, capsys):
    src, out = tmp_path / "src", tmp_path / "dst"
    train(RunConfig(task="keydoor", steps=300, seed=0, overrides=TINY), src, progress=False)
    train(RunConfig(task="keydoor_moved", steps=300, seed=0, overrides=TINY, init_from=str(src),
                    transfer=["critic"]), out, progress=False, max_episodes=0)
    line = _last_line(out, capsys)
    assert "transferred from" in line and str(src) in line and "prior" not in line


def test_a_critic_of_its_own_that_never_updated_is_still_named_as_the_prior(tmp_path, capsys):
    out = tmp_path / "own"
    train(RunConfig(task="keydoor", steps=300, seed=0, overrides=TINY), out, progress=False, max_episodes=0)
    assert "prior's" in _last_line(out, capsys)

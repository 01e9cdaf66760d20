"""`hubsgo render`: a GIF of one greedy episode with the sub-goals marked; refusals of other runs."""

import numpy as np
import pytest
import yaml

from hubsgo_ppl.cli import main
from hubsgo_ppl.diagnostics.render import (CURRENT_COLOR, GHAT_COLOR, Recording, _caption, annotate_frames,
                                           check_renderable, record_episode, render_episode)
from hubsgo_ppl.experiments.run import RunConfig, RunError, evaluate, load_run, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=60", "loop.option_steps=15"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("render") / "hubsgo"
    train(RunConfig(task="keydoor", agent="hubsgo", steps=600, seed=3, overrides=TINY), out, progress=False)
    return out


def test_gif_has_one_frame_per_step_plus_the_reset(run, tmp_path):
    from PIL import Image

    path = tmp_path / "ep.gif"
    r = render_episode(run, path, tile_size=16)
    with Image.open(path) as im:
        assert im.n_frames == r["length"] + 1 == r["frames"]
        assert im.size == (13 * 16, im.size[1]) and im.size[1] > 13 * 16      # the grid and a caption strip
        assert im.info.get("loop") == 0
    # the episode is the first one `hubsgo evaluate` runs
    ev = evaluate(run, episodes=1)
    assert ev["mean_length"] == r["length"] and ev["returns"][0] == pytest.approx(r["return"])
    assert len(r["chosen"]) >= 1 and set(r["chosen"]) <= {"yellow_key", "yellow_door", "blue_key", "blue_door", "goal"}


def test_recording_leaves_the_agent_as_it_was(run):
    resolved, env, agent, _ = load_run(run)
    with env:
        inner, select = agent.env, type(agent.high).select
        rec = record_episode(resolved, env, agent, seed=11, tile_size=8)
        assert agent.env is inner and "select" not in vars(agent.high) and type(agent.high).select is select
        assert len(rec.frames) == len(rec.achieved) == len(rec.targets) == rec.stats.length + 1
        assert rec.decisions[0][0] == 0 and [rec.names[g] for _, g, _ in rec.decisions] == rec.stats.chosen
        again = record_episode(resolved, env, agent, seed=11, tile_size=8)
        assert again.stats.chosen == rec.stats.chosen and all(np.array_equal(a, b) for a, b in zip(rec.frames, again.frames))


def test_cli_render(run, tmp_path, capsys):
    path = tmp_path / "cli.gif"
    assert main(["render", str(run), "--out", str(path), "--seed", "4", "--tile-size", "8"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{path}: ") and "frames, one greedy episode of" in out and path.is_file()
    assert main(["render", str(run), "--out", str(tmp_path / "episode.png")]) == 2      # GIF data in a .png: no
    err = capsys.readouterr().err.strip()
    assert err == f"hubsgo: error: --out {tmp_path / 'episode.png'}: render writes an animated GIF; give a path ending in .gif"
    assert not (tmp_path / "episode.png").exists()
    for flags, line in ((["--fps", "nan"], "--fps must be a positive number, got nan"),
                        (["--tile-size", "100000"], "--tile-size must be 8 to 256 pixels, got 100000")):
        assert main(["render", str(run), "--out", str(tmp_path / "x.gif"), *flags]) == 2
        assert capsys.readouterr().err.strip() == f"hubsgo: error: {line}"


def test_outlines_mark_the_current_subgoal_and_the_filters_set():
    t = 16
    frames = [np.zeros((5 * t, 5 * t, 3), np.uint8) for _ in range(3)]
    targets = [[(1, 1), (3, 1), (3, 3)]] * 3
    ghat = np.array([True, True, False])
    stats = type("S", (), {"success": True, "length": 2, "ret": 0.5, "chosen": ["k", "d"]})()
    rec = Recording(["k", "d", "g"], frames, [np.zeros(3, bool)] * 3, targets,
                    [(0, 0, ghat), (2, 1, ghat)], stats, env_seed=0, tile_size=t, filter_name="critic")
    imgs = [np.asarray(im) for im in annotate_frames(rec)]
    assert len({im.shape for im in imgs}) == 1 and imgs[0].shape[0] > 5 * t

    def edge(img, cell):
        x, y = cell
        return tuple(img[y * t, x * t + t // 2])        # a pixel on the cell's top edge

    assert edge(imgs[0], (1, 1)) == CURRENT_COLOR and edge(imgs[0], (3, 1)) == GHAT_COLOR
    assert edge(imgs[0], (3, 3)) == (0, 0, 0)           # not in Ĝt: no outline
    assert edge(imgs[2], (3, 1)) == CURRENT_COLOR and edge(imgs[2], (1, 1)) == GHAT_COLOR
    assert rec.decision_at(1)[0] == 0 and rec.decision_at(2)[:1] == (1,) and rec.decision_at(2)[2] == 2
    assert _caption(rec, 0).splitlines()[1] == "Ĝt: {k, d}"
    empty = Recording(["k", "d", "g"], frames, [np.zeros(3, bool)] * 3, targets, [(0, 0, np.zeros(3, bool))],
                      stats, env_seed=0, tile_size=t, filter_name="critic")
    assert _caption(empty, 0).splitlines()[1] == "Ĝt: {} (empty: chooses from G0)"



def test_the_caption_font_draws_the_hat_of_g_hat_t():
    from PIL import Image, ImageDraw

    from hubsgo_ppl.diagnostics.render import _font

    font = _font(14)

    def drawn(text):
        img = Image.new("L", (40, 24))
        ImageDraw.Draw(img).text((2, 2), text, font=font, fill=255)
        return np.asarray(img)

    assert (drawn("Ĝ") != drawn("G")).any() and (drawn("Ĝ") != drawn("\U0010ffff")).any()  # not the missing glyph

def _fake_run(tmp_path, **config):
    run = tmp_path / "fake"
    run.mkdir()
    (run / "config.yaml").write_text(yaml.safe_dump({"task": "stack_cubes", "family": "robosuite", "agent": "hubsgo",
                                                     "seed": 0, **config}))
    return run


def test_robosuite_run_is_refused_before_anything_is_built(tmp_path, capsys):
    run = _fake_run(tmp_path)          # no checkpoint: the refusal comes from config.yaml alone
    with pytest.raises(RunError, match="render supports MiniGrid mazes"):
        render_episode(run)
    assert main(["render", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hubsgo: error: render supports MiniGrid mazes"), err


def test_check_renderable():
    check_renderable({"family": "minigrid", "agent": "hdqn", "task": "keydoor"})
    with pytest.raises(RunError, match="render supports MiniGrid mazes; task 'push_any_one' is a robosuite task"):
        check_renderable({"family": "robosuite", "agent": "hubsgo", "task": "push_any_one"})
    with pytest.raises(RunError, match="hierarchical agents"):
        check_renderable({"family": "minigrid", "agent": "dqn", "task": "keydoor"})

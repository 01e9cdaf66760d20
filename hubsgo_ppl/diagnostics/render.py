"""``hubsgo render RUN``: an animated GIF of one greedy episode of a hierarchical run on a MiniGrid maze.

Usage::

    hubsgo render runs/keydoor-hubsgo-s0                     # writes runs/keydoor-hubsgo-s0/episode.gif
    hubsgo render runs/keydoor-hubsgo-s0 --out ep.gif --seed 7

    from hubsgo_ppl.diagnostics.render import render_episode
    info = render_episode("runs/keydoor-hubsgo-s0", "ep.gif")    # {"path", "frames", "length", ...}

The episode is the one ``hubsgo evaluate`` runs first (greedy: no exploration; HUBS-GO chooses from
Ĝt), with the same seed rule: ``--seed N`` is the evaluation seed, and the episode's env seed is
``episode_seed(N, 0)``; by default ``N`` is derived from the run's seed as ``evaluate`` does.

Each frame is MiniGrid's full-grid picture of one state: the state after reset, then one per step,
so a GIF has ``length + 1`` frames. On each frame the target cell of the current sub-goal (the one the
high level chose last, ``env.unwrapped.subgoal_target(i)``: the cell to reach, or the key or door to
face) has a thick magenta outline, and the target cells of Ĝt's sub-goals (the filter's set at that
decision; none for h-DQN, which does not filter) a thin cyan one. A caption under the grid gives the
step, the current sub-goal and Ĝt.

A Gymnasium env of one's own (family ``gym``, docs/own_env.md) is drawn from its own ``rgb_array``
frames (built with ``render_mode="rgb_array"``), with the caption and without target cells. Only
these and hierarchical agents (hubsgo, hdqn) can be drawn; other runs are refused with one line.
Frames are recorded by a wrapper around the run's env (``FrameRecorder``) and
the chosen sub-goals by wrapping the high level's ``select`` for the one episode; the agent itself is
not changed. The GIF is written with Pillow, atomically.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from ..experiments.io import atomic_path
from ..experiments.run import RunError, read_config_file
from ..specs import SpecError

__all__ = ["FrameRecorder", "Recording", "check_renderable", "read_run_config", "record_episode",
           "annotate_frames", "write_gif", "render_episode", "episode_summary", "CURRENT_COLOR", "GHAT_COLOR"]

#: outline of the current sub-goal's target cell (thick) and of Ĝt's target cells (thin)
CURRENT_COLOR = (255, 0, 255)
GHAT_COLOR = (0, 255, 255)
CAPTION_BG = (24, 24, 24)
CAPTION_FG = (240, 240, 240)


def read_run_config(run_dir: str | Path) -> dict[str, Any] | None:
    """The resolved config of a run directory from its ``config.yaml`` (cheap: no env, no checkpoint),
    or None when the file is missing or unreadable (the checkpoint's copy is then the one to use)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunError(f"{run_dir}: no such run directory; pass the --out folder of `hubsgo train`")
    return read_config_file(run_dir)


def check_renderable(resolved: dict[str, Any], what: str = "render") -> None:
    """Refuse (RunError, one line) a run that :func:`render_episode` cannot draw: not a MiniGrid maze,
    or an agent without sub-goals (the flat baselines)."""
    from ..agents.factory import HIERARCHICAL

    family, task = resolved.get("family"), resolved.get("task", "?")
    if family not in ("minigrid", "gym"):
        raise RunError(f"{what} supports MiniGrid mazes; task {task!r} is a {family or 'non-maze'} task")
    agent = resolved.get("agent")
    if agent not in HIERARCHICAL:
        raise RunError(f"{what} draws the sub-goals of hierarchical agents ({', '.join(HIERARCHICAL)}); "
                       f"this run's agent is {agent!r}")


class FrameRecorder(gym.Wrapper):
    """Records, after ``reset`` and after every ``step``, MiniGrid's full-grid frame, the achieved
    sub-goals and every sub-goal's target cell (keys move when carried, so targets are per frame)."""

    def __init__(self, env: gym.Env, tile_size: int = 32):
        super().__init__(env)
        self.tile_size = int(tile_size)
        self.frames: list[np.ndarray] = []
        self.achieved: list[np.ndarray] = []
        self.targets: list[list[tuple[int, int]]] = []

    def _capture(self, info: dict[str, Any]) -> None:
        u = self.env.unwrapped
        if not callable(getattr(u, "get_frame", None)):         # a Gymnasium env of one's own: its frame
            frame = self.env.render()
            if not (isinstance(frame, np.ndarray) and frame.ndim == 3 and frame.shape[2] == 3):
                raise RunError("render: the env returned no rgb_array frame from render(); give it "
                               "render_mode='rgb_array' (an H x W x 3 uint8 array)")
            self.frames.append(np.asarray(frame, dtype=np.uint8))
            self.achieved.append(np.asarray(info["subgoals"], dtype=bool).copy())
            self.targets.append([])
            return
        self.frames.append(np.asarray(u.get_frame(highlight=False, tile_size=self.tile_size), dtype=np.uint8))
        self.achieved.append(np.asarray(info["subgoals"], dtype=bool).copy())
        self.targets.append([tuple(int(c) for c in u.subgoal_target(i)) for i in range(len(u.subgoal_names))])

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        self.frames, self.achieved, self.targets = [], [], []
        self._capture(info)
        return obs, info

    def step(self, action: Any):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._capture(info)
        return obs, reward, terminated, truncated, info


@dataclasses.dataclass
class Recording:
    """One recorded episode: frames (length + 1), and the high level's decisions as
    ``(frame index, sub-goal index, Ĝt mask or None)``: the decision holds from that frame on."""

    names: list[str]
    frames: list[np.ndarray]
    achieved: list[np.ndarray]
    targets: list[list[tuple[int, int]]]
    decisions: list[tuple[int, int, np.ndarray | None]]
    stats: Any                      # the loop's EpisodeStats
    env_seed: int
    tile_size: int
    filter_name: str = "none"       # the loop's filter: "critic" (HUBS-GO) or "none" (h-DQN)

    def decision_at(self, frame: int) -> tuple[int, np.ndarray | None, int]:
        """(sub-goal, Ĝt, option number from 1) in force at ``frame``."""
        current = None
        for k, (start, g, ghat) in enumerate(self.decisions):
            if start > frame:
                break
            current = (g, ghat, k + 1)
        if current is None:          # cannot happen: the first decision is taken on frame 0
            raise RuntimeError(f"no high-level decision before frame {frame}")
        return current


def _eval_env_seed(resolved: dict[str, Any], seed: int | None) -> int:
    from ..agents.loop import episode_seed

    base = int(resolved["seed"]) + 1_000_003 if seed is None else int(seed)     # as experiments.run.evaluate
    return episode_seed(base, 0)


def record_episode(resolved: dict[str, Any], env: gym.Env, agent: Any, seed: int | None = None,
                   tile_size: int = 32) -> Recording:
    """Run one greedy episode of a loaded hierarchical ``agent`` (``experiments.run.load_run``) and
    record it. ``agent.env`` and ``agent.high.select`` are wrapped for the episode and restored after."""
    check_renderable(resolved)
    if not (hasattr(agent, "high") and hasattr(agent, "filter") and hasattr(agent, "env")):
        raise RunError(f"agent {resolved.get('agent')!r} is not a hierarchical loop; cannot record its sub-goals")
    names = list(env.unwrapped.subgoal_names)
    drawn = _rgb_env(resolved) if resolved.get("family") == "gym" else agent.env
    recorder = FrameRecorder(drawn, tile_size=tile_size)
    decisions: list[tuple[int, int, np.ndarray | None]] = []
    given = bool(getattr(getattr(agent, "cfg", None), "filter_given_achieved", False))
    select = agent.high.select

    def recording_select(obs: np.ndarray, allowed: np.ndarray, explore_eps: float) -> int:
        g = select(obs, allowed, explore_eps)
        achieved = recorder.achieved[-1]
        ghat = agent.filter.allowed(achieved if given else None)      # what the loop read (no RNG used)
        decisions.append((len(recorder.frames) - 1, int(g), None if ghat is None else np.asarray(ghat, bool).copy()))
        return g

    env_seed = _eval_env_seed(resolved, seed)
    original_env = agent.env
    agent.env = recorder
    agent.high.select = recording_select
    try:
        stats = agent.run_episode(train=False, seed=env_seed)
    finally:
        agent.env = original_env
        if drawn is not original_env:
            drawn.close()
        with contextlib.suppress(AttributeError):
            del agent.high.select         # the instance attribute; the class's method shows again
    return Recording(names, recorder.frames, recorder.achieved, recorder.targets, decisions, stats,
                     env_seed, int(tile_size), str(getattr(agent.filter, "name", "none")))


def _rgb_env(resolved: dict[str, Any]) -> gym.Env:
    """The run's env (family gym) built to render ``rgb_array`` frames."""
    from ..envs.subset import make_subset

    kwargs = dict((resolved.get("hyper") or {}).get("env") or {})
    try:
        return make_subset(resolved["task_ref"], resolved.get("subgoals"), render_mode="rgb_array", **kwargs)
    except (TypeError, SpecError) as exc:     # SpecError: the kwargs check, which names options.kwargs
        if isinstance(exc, SpecError) and "'render_mode'" not in str(exc):
            raise
        raise RunError(f"render: the env of task {resolved.get('task')!r} cannot be built with render_mode="
                       "'rgb_array' (its constructor or factory takes no render_mode argument); give it one, "
                       "and a render() that returns an H x W x 3 uint8 frame") from None


def _font(size: int):
    """matplotlib's DejaVu Sans (it has the Ĝ of Ĝt, Pillow's own font does not), else Pillow's font."""
    import matplotlib
    from PIL import ImageFont

    try:
        return ImageFont.truetype(str(Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"), size)
    except OSError:
        pass
    try:
        return ImageFont.load_default(size=size)
    except TypeError:                      # Pillow < 10.1: the fixed bitmap font
        return ImageFont.load_default()


def _wrap(draw: Any, text: str, font: Any, width: int) -> list[str]:
    """Greedy word wrap of ``text`` to ``width`` pixels (a word longer than a line gets its own line)."""
    lines: list[str] = []
    for para in text.split("\n"):
        line = ""
        for word in para.split(" "):
            trial = word if not line else f"{line} {word}"
            if line and draw.textlength(trial, font=font) > width:
                lines.append(line)
                line = word
            else:
                line = trial
        lines.append(line)
    return lines


def _caption(rec: Recording, i: int) -> str:
    g, ghat, option = rec.decision_at(i)
    last = len(rec.frames) - 1
    text = f"step {i}/{last}  option {option}: sub-goal {rec.names[g]}"
    if i == last:
        text += "  (success)" if rec.stats.success else "  (episode over, no success)"
    if ghat is None:
        text += ("\nĜt = G0 (no critic update yet)" if rec.filter_name == "critic"
                 else "\nno filter: chooses from G0")
    elif not np.any(ghat):
        text += "\nĜt: {} (empty: chooses from G0)"
    else:
        text += "\nĜt: {" + ", ".join(n for n, m in zip(rec.names, ghat) if m) + "}"
    return text


def annotate_frames(rec: Recording, font_size: int | None = None) -> list[Any]:
    """PIL images of the recording: outlines on the target cells and a caption strip (all the same size)."""
    from PIL import Image, ImageDraw

    t = rec.tile_size
    font = _font(font_size or max(10, t * 2 // 5))
    h, w = rec.frames[0].shape[:2]
    probe = ImageDraw.Draw(Image.new("RGB", (w, 10)))
    captions = [_wrap(probe, _caption(rec, i), font, w - 8) for i in range(len(rec.frames))]
    ascent, descent = font.getmetrics() if hasattr(font, "getmetrics") else (11, 3)
    line_h = ascent + descent + 2
    strip = 6 + line_h * max(len(c) for c in captions)
    thick, thin = max(2, t // 8), max(1, t // 16)
    images = []
    for i, (frame, lines) in enumerate(zip(rec.frames, captions)):
        img = Image.new("RGB", (w, h + strip), CAPTION_BG)
        img.paste(Image.fromarray(frame), (0, 0))
        draw = ImageDraw.Draw(img)
        g, ghat, _ = rec.decision_at(i)
        targets = rec.targets[i]
        if targets and ghat is not None:        # (a Gymnasium env of one's own has no target cells)
            for j in np.flatnonzero(ghat):
                if j != g:
                    x, y = targets[j]
                    draw.rectangle([x * t, y * t, (x + 1) * t - 1, (y + 1) * t - 1], outline=GHAT_COLOR, width=thin)
        if targets:
            x, y = targets[g]
            draw.rectangle([x * t, y * t, (x + 1) * t - 1, (y + 1) * t - 1], outline=CURRENT_COLOR, width=thick)
        for k, line in enumerate(lines):
            draw.text((4, h + 3 + k * line_h), line, fill=CAPTION_FG, font=font)
        images.append(img)
    return images


def write_gif(images: list[Any], path: str | Path, fps: float = 6.0, hold_last_ms: int = 1500) -> Path:
    """Write PIL images as a looping GIF, atomically; the last frame is held ``hold_last_ms``."""
    if not images:
        raise ValueError("no frames to write")
    if not (math.isfinite(fps) and fps > 0):
        raise RunError(f"--fps must be a positive number, got {fps}")
    step = max(20, int(round(1000 / fps)))
    durations = [step] * (len(images) - 1) + [max(step, int(hold_last_ms))]
    path = Path(path)
    with atomic_path(path, suffix=".gif") as tmp:
        # disposal 1 and no optimisation keep one GIF frame per image even where two look alike
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=durations,
                       loop=0, optimize=False, disposal=1)
    return path


def render_episode(run_dir: str | Path, path: str | Path | None = None, seed: int | None = None,
                   tile_size: int = 32, fps: float = 6.0) -> dict[str, Any]:
    """Record one greedy episode of the run in ``run_dir`` and write it as a GIF to ``path`` (default
    ``RUN/episode.gif``). Returns ``{"path", "frames", "length", "return", "success", "chosen",
    "env_seed"}``. Refuses (RunError) runs that are not MiniGrid mazes or not hierarchical."""
    from ..experiments.run import load_run

    run_dir = Path(run_dir)
    if not 8 <= tile_size <= 256:
        raise RunError(f"--tile-size must be 8 to 256 pixels, got {tile_size}")
    if path is not None and Path(path).suffix.lower() != ".gif":
        raise RunError(f"--out {path}: render writes an animated GIF; give a path ending in .gif")
    cfg = read_run_config(run_dir)
    if cfg is not None:
        check_renderable(cfg)           # before building the env: a robosuite run is refused cheaply
    resolved, env, agent, _ = load_run(run_dir)
    with contextlib.closing(env):
        rec = record_episode(resolved, env, agent, seed=seed, tile_size=tile_size)
    out = Path(path) if path is not None else run_dir / "episode.gif"
    write_gif(annotate_frames(rec), out, fps=fps)
    return episode_summary(rec, out)


def episode_summary(rec: Recording, path: Path | None) -> dict[str, Any]:
    """Plain data about a recorded episode (written into review.json)."""
    s = rec.stats
    return {"path": None if path is None else str(path), "frames": len(rec.frames), "length": int(s.length),
            "return": float(s.ret), "success": bool(s.success), "chosen": list(s.chosen),
            "env_seed": int(rec.env_seed)}

"""``hubsgo revise RUN --model NEW_SPEC.yaml [--steps TOTAL]``: continue a HUBS-GO run with a revised
critic spec (the human's side of the mixed-initiative loop, after ``hubsgo review``).

The new spec may add or drop sub-goals, add, drop or re-sign edges, and change the graph preset, the
prior, the likelihood or the inference settings. Its sub-goals must be sub-goals the task's catalogue
defines (the task can evaluate nothing else); a spec naming another is refused in one line that
names it and the catalogue's sub-goals.

*Dropping a sub-goal* removes it from the run's candidate set: the run continues on the task with
only the spec's sub-goals (:mod:`hubsgo_ppl.envs.subset`), so the high level has no output for it and
can no longer choose it, the critic has no indicator for it, and the low level no goal for it.
*Adding* one (a catalogue sub-goal the run does not have, e.g. one dropped by an earlier revision)
gives each of them a new output, indicator and goal.

What carries over, matched by name (edges by unordered name pair), and how new parts start, is listed
in :mod:`hubsgo_ppl.experiments.transfer`: in short, the critic's learned unary and pairwise factors
of every persisting sub-goal and edge (bit for bit), the high level's Q outputs of persisting
sub-goals (bit for bit; new outputs: the mean of the kept ones), the low level, the replay buffers
(remapped), the counters and schedules. A revision that changes the critic's objective (its
sub-goals, edges, signs, graph, prior, likelihood or inference settings) restarts the critic's Adam
state and baseline, and the low level's goal weights until the next critic update, so that the critic
re-fits the changed objective from fresh steps; one that changes none of them carries them over too,
and the run continues exactly as if it had not been revised.

The revision is made at the run's checkpoint (the per-episode logs are cut back to it, as on
``--resume``) and recorded in the run directory::

    revisions.csv                one line per revision: number, env step, episode, what changed
    revisions/NNN/spec_before.yaml   the critic spec before revision NNN (as the run used it)
    revisions/NNN/spec_after.yaml    the spec after it
    revisions/NNN/revision.json      the line of revisions.csv with the lists in full

config.yaml and the checkpoint then hold the revised spec (``revision``: how many revisions the run
has had); the learning curve marks each revision. Training continues up to ``--steps`` (the new total
budget; default: the run's). A revision is deterministic: the same revision at the same step of the
same seeded run gives the same files, metrics.csv included.

    hubsgo train keydoor_incorrect --steps 40000 --stop-at 13000 --out runs/kdi
    hubsgo review runs/kdi
    hubsgo revise runs/kdi --model my-keydoor-spec.yaml

    from hubsgo_ppl.experiments.revise import revise
    revise("runs/kdi", "my-keydoor-spec.yaml")
"""

from __future__ import annotations

import contextlib
import copy
import csv
import io
import sys
from pathlib import Path
from typing import Any

from ..envs import get_task
from ..envs.subset import catalogue_order, check_subset
from .checkpoint import CHECKPOINT, check_episode_log
from .lock import run_folder_lock
from .logger import CSVOutput
from .io import truncate_csv, write_json, write_text, write_yaml
from .run import (EPISODE_LOGS, REVISIONS_CSV, RunConfig, RunError, _build, _save,
                  g_star_table, note_unlinked_goals, plot_run_curve, run_config, run_dir_checkpoint, train,
                  warn_goals_left_out)
from .remap import TransferError, revise_agent_state
from .restore import restore

__all__ = ["revise", "apply_revision", "load_revision_spec", "spec_changes", "objective_unchanged", "REVISIONS_DIR", "REVISION_FIELDS"]

REVISIONS_DIR = "revisions"
#: the columns of revisions.csv (lists joined with spaces)
REVISION_FIELDS = ("revision", "env_steps", "episode", "spec_before", "spec_after", "subgoals_added",
                   "subgoals_dropped", "edges_added", "edges_dropped", "edges_resigned", "graph", "prior",
                   "likelihood", "inference", "steps")


def load_revision_spec(spec: str | Path, resolved: dict[str, Any]):
    """The revised spec, validated, its sub-goals checked against the run's task catalogue and put in
    its order. Refuses (SpecError, one line) a sub-goal the catalogue does not define."""
    from ..specs import for_family, load_model_spec

    new = for_family(load_model_spec(spec), resolved["family"])
    catalogue = list(get_task(resolved["task_ref"]).catalogue.names)
    check_subset(new.subgoals, catalogue, f"{spec} (for task {resolved['task']!r})")
    return new.model_copy(update={"subgoals": catalogue_order(new.subgoals, catalogue)})


def _edge_signs(spec: dict[str, Any]) -> dict[frozenset, str]:
    return {frozenset((u, v)): str(s) for u, v, s in spec.get("edges", [])}


def spec_changes(before: dict[str, Any], after: dict[str, Any]) -> dict[str, Any]:
    """What a revision changes, spec against spec (the edges as the human wrote them)."""
    b_names, a_names = list(before["subgoals"]), list(after["subgoals"])
    b_edges, a_edges = _edge_signs(before), _edge_signs(after)

    def label(pair: frozenset, spec: dict[str, Any]) -> str:
        for u, v, _ in spec.get("edges", []):
            if frozenset((u, v)) == pair:
                return f"{u}--{v}"
        return "--".join(sorted(pair))

    def changed(key: str) -> str:
        return "changed" if before.get(key) != after.get(key) else "same"

    return {"subgoals_added": [n for n in a_names if n not in b_names],
            "subgoals_dropped": [n for n in b_names if n not in a_names],
            "edges_added": [label(p, after) for p in a_edges if p not in b_edges],
            "edges_dropped": [label(p, before) for p in b_edges if p not in a_edges],
            "edges_resigned": [f"{label(p, after)}:{b_edges[p]}->{s}" for p, s in a_edges.items()
                               if p in b_edges and b_edges[p] != s],
            "graph": changed("graph"), "prior": changed("prior"), "likelihood": changed("likelihood"),
            "inference": changed("inference")}


def objective_unchanged(changes: dict[str, Any]) -> bool:
    """Whether a revision's ``spec_changes`` leave the critic's objective as it was: no sub-goal or edge
    added, dropped or re-signed, and the same graph, prior, likelihood and inference settings."""
    return (not any(changes[k] for k in ("subgoals_added", "subgoals_dropped", "edges_added", "edges_dropped",
                                         "edges_resigned"))
            and all(changes[k] == "same" for k in ("graph", "prior", "likelihood", "inference")))


def _write_revisions_csv(run_dir: Path, upto: int) -> None:
    """revisions.csv from revisions/001 .. revisions/``upto`` (a folder left by a revision that never
    reached its checkpoint is not listed, and is overwritten by the next one)."""
    import json

    buf = io.StringIO(newline="")
    writer = csv.DictWriter(buf, fieldnames=REVISION_FIELDS, extrasaction="ignore")
    writer.writeheader()
    for k in range(1, upto + 1):
        path = run_dir / REVISIONS_DIR / f"{k:03d}" / "revision.json"
        if not path.is_file():
            continue
        rec = json.loads(path.read_text())
        writer.writerow({f: " ".join(map(str, rec[f])) if isinstance(rec.get(f), list) else rec.get(f)
                         for f in REVISION_FIELDS})
    write_text(run_dir / REVISIONS_CSV, buf.getvalue())


def _end_history(run_dir: Path, episodes: int, env_steps: int, settled: bool, g_star: dict[str, Any]) -> None:
    """The last row of critic_history.csv (cut back with the logs) again, now with the marginals of the
    revised critic that subgoals.json reads G* from, as a finished run's history ends."""
    path = run_dir / "critic_history.csv"
    if path.is_file():
        CSVOutput(path).write({"episode": episodes, "env_steps": env_steps, "critic": "settled" if settled else "final",
                               **{n: round(float(m), 5) for n, m in g_star["marginals"].items()}})


def apply_revision(run_dir: str | Path, new_spec: str | Path, steps: int | None = None,
                   train_after: bool = True) -> dict[str, Any]:
    """Revise the run's critic spec at its checkpoint (module docstring) without training; returns the
    revision's record (what revision.json holds). A run that has taken its budget needs ``steps`` above
    it, unless nothing is to be trained after (``train_after`` False, ``steps`` None): the run then stays
    finished, and its subgoals.json is rewritten with the revised critic's G*, read from the same recent
    successes (``record["finished"]``)."""
    if not (Path(run_dir) / CHECKPOINT).is_file():     # refused before the lock creates anything
        run_dir_checkpoint(Path(run_dir))
    with run_folder_lock(run_dir, flag=""):     # no train or other revision writes the folder meanwhile
        return _apply_revision(Path(run_dir), new_spec, steps, train_after)


def _apply_revision(run_dir: Path, new_spec: str | Path, steps: int | None, train_after: bool) -> dict[str, Any]:
    ckpt = run_dir_checkpoint(run_dir)
    check_episode_log(run_dir, int(ckpt["episodes"]))      # its rows are cut back to the checkpoint below
    old = ckpt["config"]
    if old.get("agent") != "hubsgo" or "model_spec" not in old:
        raise RunError(f"{run_dir}: agent {old.get('agent')!r} has no sub-goal critic to revise; "
                       "revise a run trained with --agent hubsgo")
    if steps is not None and int(steps) <= 0:
        raise RunError(f"--steps must be a positive number of env steps, got {steps}")
    spec = load_revision_spec(new_spec, old)
    restore(run_dir / CHECKPOINT, ckpt)[1].close()    # a damaged checkpoint: one line, before anything is written
    done = int(ckpt["env_steps"])
    total = int(steps) if steps is not None else int(old["hyper"]["steps"])
    finished = total <= done and steps is None and not train_after
    if total <= done and not finished:
        raise RunError(f"{run_dir}: the run has already taken {done:,} of {'the' if steps else 'its'} {total:,} env "
                       f"steps; pass --steps TOTAL above {done} to train on after the revision")
    new = copy.deepcopy(old)
    new["model_spec"] = spec.model_dump(mode="json")
    new["model"] = spec.name
    catalogue = list(get_task(old["task_ref"]).catalogue.names)
    if list(spec.subgoals) == catalogue:
        new.pop("subgoals", None)
    else:
        new["subgoals"] = list(spec.subgoals)
    new["hyper"]["steps"] = total
    number = int(old.get("revision", 0)) + 1
    new["revision"] = number

    changes = spec_changes(old["model_spec"], new["model_spec"])
    if objective_unchanged(changes):
        after = "G* is read as it was" if finished else "the run goes on as it would have"
        print(f"hubsgo: note: {new_spec} asks for the critic the run already has; it is recorded as revision "
              f"{number}, and {after}", file=sys.stderr)
    warn_goals_left_out(spec.name, old["task_ref"], new.get("subgoals"))
    note_unlinked_goals(new)
    env, agent = _build(new)
    with contextlib.closing(env):
        try:
            state, kept = revise_agent_state(ckpt["agent"], agent, same_objective=objective_unchanged(changes))
            agent.load_state_dict(state)
        except TransferError as exc:
            raise RunError(f"{run_dir}: cannot revise: {exc}") from None
        record = {"revision": number, "env_steps": done, "episode": int(ckpt["episodes"]),
                  "spec_before": old.get("model"), "spec_after": spec.name, "source": str(new_spec),
                  **changes, "steps": total,
                  "kept": {"theta": len(kept["subgoals_kept"]), "couplings": len(kept["edges_kept"]),
                           "high_outputs": kept["high_outputs_kept"]},
                  "new": {"subgoals": kept["subgoals_new"], "edges": kept["edges_new"]},
                  "critic_learned": kept["learned"], "critic_optimizer": kept["critic_optimizer"], "pending_discarded": kept["pending_discarded"],
                  "outcomes_kept": kept["outcomes_kept"], "finished": finished}
        folder = run_dir / REVISIONS_DIR / f"{number:03d}"
        write_yaml(folder / "spec_before.yaml", old["model_spec"])
        write_yaml(folder / "spec_after.yaml", new["model_spec"])
        write_json(folder / "revision.json", record)
        for name in EPISODE_LOGS:           # as --resume does: the logs end at the checkpoint
            truncate_csv(run_dir / name, "episode", int(ckpt["episodes"]))
        _save(run_dir, new, agent, float(ckpt.get("wall_time", 0.0)))      # the revision takes effect here
        g_star = g_star_table(agent, list(env.unwrapped.subgoal_names), run_dir) if finished else None
    write_yaml(run_dir / "config.yaml", new)
    _write_revisions_csv(run_dir, number)
    if g_star is not None:      # the run stays ended: its G* is now the revised critic's
        write_json(run_dir / "subgoals.json", g_star)
        _end_history(run_dir, int(ckpt["episodes"]), done, agent.settled_step is not None, g_star)
    else:
        (run_dir / "subgoals.json").unlink(missing_ok=True)     # G* of the old spec; rewritten when the run ends
    plot_run_curve(run_dir, new)
    return record


def revise(run_dir: str | Path, new_spec: str | Path, steps: int | None = None, progress: bool = True,
           stop_at: int | None = None, train_after: bool = True) -> dict[str, Any]:
    """Revise the run's critic spec (:func:`apply_revision`) and, with ``train_after``, continue training
    it to ``steps`` (``stop_at``: pause there, as ``train``). Returns ``{"revision": record, "summary":
    train's summary or None}``."""
    record = apply_revision(run_dir, new_spec, steps, train_after=train_after)
    summary = None
    if train_after:
        task = run_config(run_dir)["task_ref"]
        summary = train(RunConfig(task=task), run_dir, resume=True, progress=progress, stop_at=stop_at)
    return {"revision": record, "summary": summary}

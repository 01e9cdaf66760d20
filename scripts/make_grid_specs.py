"""Write the critic specs of the prior x likelihood grid (sweeps/specs/<task>-<prior>-<likelihood>.yaml):
every registered prior with every registered likelihood, each at its default parameters, on the task's
default spec's sub-goals and human edges (models/<task>-specific.yaml). Used by sweeps/critic_grid.yaml.
The TD likelihoods (Eq. 4 and its heavier-tailed variants) also at ``scale`` 0.1, the size of the
high level's TD residuals once its values are learned (sweeps/specs/<task>-<prior>-<likelihood>-scale01.yaml),
and the shipped prior with the paper's Gaussian likelihood at that scale (<task>-shipped-gaussian-scale01.yaml),
used by sweeps/critic_grid_matched.yaml.
Also the default specs with the outcome evidence tempered less (sweeps/specs/<task>-power1.yaml and
<task>-power05.yaml, the outcome likelihood's ``power`` at 1.0 and 0.5), used by sweeps/critic_power.yaml.
Run from the repository root: ``python scripts/make_grid_specs.py``.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from hubsgo_ppl.infer.likelihoods import LIKELIHOODS
from hubsgo_ppl.infer.priors import PRIORS

ROOT = Path(__file__).resolve().parents[1]
TASKS = ("keydoor", "threepair")
#: the TD likelihoods, and the scale at which they are also measured: about the size of the high
#: level's TD residuals on the mazes once Q is learned (at scale 1 the evidence is too weak to move q)
TD_LIKELIHOODS = ("gaussian", "laplace", "student_t")
MATCHED_SCALE = 0.1
POWER_TASKS = ("keydoor", "keydoor_n65", "threepair", "fourroom", "detour")


def write(path: Path, spec: dict, header: str) -> None:
    path.write_text(f"# {header} (scripts/make_grid_specs.py)\n" + yaml.safe_dump(spec, sort_keys=False, width=120))
    print(path.relative_to(ROOT))


def main() -> None:
    out = ROOT / "sweeps" / "specs"
    out.mkdir(exist_ok=True)
    for task in TASKS:
        base = yaml.safe_load((ROOT / "models" / f"{task}-specific.yaml").read_text())
        for prior in sorted(PRIORS):
            for lik in sorted(LIKELIHOODS):
                spec = {**base, "name": f"{task}-{prior}-{lik}", "prior": {"name": prior},
                        "likelihood": {"name": lik},
                        # q starts at the prior where the guide can hold it, else at the edge signs
                        "inference": {**base["inference"], "init": "prior" if prior != "beta_bernoulli" else "edges"}}
                write(out / f"{task}-{prior}-{lik}.yaml", spec,
                      f"{task}: prior {prior}, likelihood {lik}, both at their default parameters")
    for task in TASKS:
        base = yaml.safe_load((ROOT / "models" / f"{task}-specific.yaml").read_text())
        for prior in sorted(PRIORS):
            for lik in TD_LIKELIHOODS:
                spec = {**base, "name": f"{task}-{prior}-{lik}-scale01", "prior": {"name": prior},
                        "likelihood": {"name": lik, "scale": MATCHED_SCALE},
                        "inference": {**base["inference"], "init": "prior" if prior != "beta_bernoulli" else "edges"}}
                write(out / f"{task}-{prior}-{lik}-scale01.yaml", spec,
                      f"{task}: prior {prior} at its default parameters, likelihood {lik} at scale {MATCHED_SCALE}")
        spec = {**base, "name": f"{task}-shipped-gaussian-scale01",
                "likelihood": {"name": "gaussian", "scale": MATCHED_SCALE}}
        write(out / f"{task}-shipped-gaussian-scale01.yaml", spec,
              f"{task}: the shipped prior, the Gaussian likelihood (Eq. 4) at scale {MATCHED_SCALE}")
    for task in POWER_TASKS:
        base = yaml.safe_load((ROOT / "models" / f"{task}-specific.yaml").read_text())
        for suffix, power in (("power1", 1.0), ("power05", 0.5)):
            spec = {**base, "name": f"{task}-{suffix}", "likelihood": {**base["likelihood"], "power": power}}
            write(out / f"{task}-{suffix}.yaml", spec, f"{task}: the default spec with the outcome evidence at power {power}")


if __name__ == "__main__":
    main()

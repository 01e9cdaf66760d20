"""Write the critic specs of the prior x likelihood grid (sweeps/specs/<task>-<prior>-<likelihood>.yaml):
every registered prior with every registered likelihood, each at its default parameters, on the task's
default spec's sub-goals and human edges (models/<task>-specific.yaml). Used by sweeps/critic_grid.yaml.
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
    for task in POWER_TASKS:
        base = yaml.safe_load((ROOT / "models" / f"{task}-specific.yaml").read_text())
        for suffix, power in (("power1", 1.0), ("power05", 0.5)):
            spec = {**base, "name": f"{task}-{suffix}", "likelihood": {**base["likelihood"], "power": power}}
            write(out / f"{task}-{suffix}.yaml", spec, f"{task}: the default spec with the outcome evidence at power {power}")


if __name__ == "__main__":
    main()

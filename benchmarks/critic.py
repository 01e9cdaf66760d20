"""Critic benchmark (not a test): update time, sampler throughput, exact log Z, learning budgets.

Run: ``.venv/bin/python benchmarks/critic.py`` (one CPU thread; results go to docs/benchmarks.md).

``--floor SPEC`` times, interleaved in one run on a maze spec, one critic update the default way
(``inference.jit``: the TraceGraph_ELBO step compiled by CompiledTraceGraph_ELBO, the MH sweeps
compiled with numba) against the eager update (``jit: false``), a bare eager ``TraceGraph_ELBO`` step
with the same residuals, particles and baseline but an independent Bernoulli guide (Pyro's own cost
per step), and the MH burn-in sweeps compiled and in the eager torch loop. Both critics take
bit-identical steps (tests/infer/test_compiled.py), so the ratio is pure speed.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import pyro
import torch

from hubsgo_ppl.distributions import PairwiseMRF
from hubsgo_ppl.graph import SubgoalGraph
from hubsgo_ppl.infer.critic import InferenceConfig, SubgoalCritic, TDBatch
from hubsgo_ppl.infer.mh import MRFMHKernel, run_chains


def sparse_graph(n: int, seed: int = 0) -> SubgoalGraph:
    """A chain plus n/2 random signed chords: a 'specific' graph of a realistic density."""
    g = torch.Generator().manual_seed(seed)
    names = [f"g{i}" for i in range(n)]
    edges = {(i, i + 1): 1 for i in range(n - 1)}
    while len(edges) < n - 1 + n // 2 and n > 2:
        a, b = sorted(torch.randint(0, n, (2,), generator=g).tolist())
        if a != b and (a, b) not in edges:
            edges[(a, b)] = -1
    return SubgoalGraph(names, [(names[a], names[b], s) for (a, b), s in edges.items()])


def td_batch(n: int, b: int = 32) -> TDBatch:
    g = torch.Generator().manual_seed(1)
    q = torch.randn(b, n, generator=g)
    return TDBatch(q[:, 0], q, torch.rand(b, generator=g), torch.full((b,), 0.9))


def time_updates(n: int, repeats: int, pyro_validation: str = "first") -> float:
    critic = SubgoalCritic(sparse_graph(n), config=InferenceConfig(pyro_validation=pyro_validation), seed=0)
    batch = td_batch(n)
    for _ in range(3):
        critic.update(batch)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        critic.update(batch)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def sampler_rates(n: int = 10) -> tuple[float, float]:
    graph = sparse_graph(n)
    g = torch.Generator().manual_seed(0)
    theta, coupling = torch.randn(n, generator=g), torch.randn(graph.num_edges, generator=g)
    t = time.perf_counter()
    run_chains(theta, coupling, graph.edge_index, num_chains=64, num_steps=200, generator=g)
    batched = 64 * 200 / (time.perf_counter() - t)
    kernel = MRFMHKernel(theta, coupling, graph.edge_index, seed=0)
    mcmc = pyro.infer.MCMC(kernel, num_samples=1000, warmup_steps=0, disable_progbar=True)
    t = time.perf_counter()
    mcmc.run()
    return batched, 1000 / (time.perf_counter() - t)


def log_z_time(n: int = 20) -> float:
    graph = sparse_graph(n)
    theta = torch.randn(n, requires_grad=True)
    coupling = torch.randn(graph.num_edges, requires_grad=True)
    t = time.perf_counter()
    PairwiseMRF(theta, coupling, graph.edge_index).log_partition().backward()
    return time.perf_counter() - t


def keydoor_budget(preset: str, max_updates: int = 600, seed: int = 0) -> int | None:
    graph = SubgoalGraph(["a1", "b1", "a2", "b2"], [("a1", "b1", 1), ("a2", "b2", 1), ("a1", "a2", -1), ("b1", "b2", -1)])
    critic = SubgoalCritic(graph.preset(preset), seed=seed)
    good = torch.tensor([[1.0, 1, 0, 0], [0.0, 0, 1, 1]])

    def residuals(w):
        ok = w[..., 0] * w[..., 1] * (1 - w[..., 2]) * (1 - w[..., 3]) + (1 - w[..., 0]) * (1 - w[..., 1]) * w[..., 2] * w[..., 3]
        return (2.0 * (1.0 - ok)).unsqueeze(-1).expand(w.shape[:-1] + (4,))

    for step in range(1, max_updates + 1):
        critic.update(residuals)
        if step % 10 == 0 and float(critic.distribution().log_prob(good).exp().sum()) > 0.8:
            return step
    return None


def pyro_floor(spec: str = "fourroom-specific", rounds: int = 5, repeats: int = 40) -> dict[str, float]:
    """Best-of-``rounds`` ms per call of: a critic update on ``spec`` (compiled, the default, and eager),
    a bare TraceGraph_ELBO step with an independent Bernoulli guide on the same residuals (no MH), and
    the update's MH burn-in alone (numba and the eager torch loop)."""
    import pyro.distributions as dist
    from pyro.infer import TraceGraph_ELBO

    from hubsgo_ppl.infer.mh import _eager_sweeps, single_site_sweep
    from hubsgo_ppl.specs import load_model_spec

    critic = SubgoalCritic.from_spec(load_model_spec(spec), seed=0)
    eager_spec = load_model_spec(spec)
    eager_spec.inference.jit = False
    eager = SubgoalCritic.from_spec(eager_spec, seed=0)
    n, cfg = critic.n, critic.config
    g = torch.Generator().manual_seed(1)
    batch = TDBatch(torch.rand(64, generator=g), torch.rand(64, n, generator=g), torch.zeros(64),
                    torch.full((64,), 0.9), available=torch.rand(64, n, generator=g) > 0.2)
    if critic.likelihood.evidence == "outcomes":    # the shipped specs: 20 recent successes' achieved sets
        batch.outcomes = (torch.rand(20, n, generator=g) > 0.5).float()
    theta = torch.zeros(n, requires_grad=True)

    def model():                # Pyro's own step on the same particles, with Eq. 4's Gaussian on the residuals
        w = pyro.sample("w", dist.Bernoulli(torch.full((n,), 0.5)).to_event(1))
        r = batch.residuals(w)
        pyro.sample("td", dist.Normal(r, 0.1).to_event(1), obs=torch.zeros(r.shape))

    def guide():
        pyro.sample("w", dist.Bernoulli(logits=pyro.param("theta", theta)).to_event(1),
                    infer={"baseline": {"use_decaying_avg_baseline": True, "baseline_beta": cfg.baseline_beta}})

    elbo = TraceGraph_ELBO(num_particles=cfg.num_samples, vectorize_particles=True, max_plate_nesting=0)
    store = {"params": {}, "constraints": {}}

    def bare_step():
        with pyro.get_param_store().scope(state=store), pyro.validation_enabled(False):
            elbo.loss_and_grads(model, guide)

    chains = critic._chains.clone()
    theta, coupling = critic._theta.detach(), critic._coupling.detach()
    calls = {
        "critic.update (compiled, default)": lambda: critic.update(batch),
        "critic.update, inference.jit: false": lambda: eager.update(batch),
        "bare eager TraceGraph_ELBO step": bare_step,
        f"{cfg.burn_in} MH sweeps (numba)": lambda: single_site_sweep(chains, theta, coupling, critic.graph.edge_index,
                                                                   g, sweeps=cfg.burn_in),
        f"{cfg.burn_in} MH sweeps (eager torch loop)": lambda: _eager_sweeps(chains, theta, coupling,
                                                                          critic.graph.edge_index, g, cfg.burn_in),
    }
    for call in calls.values():
        for _ in range(5):
            call()
    best = {name: math.inf for name in calls}
    for _ in range(rounds):                       # interleaved, so machine load hits all three alike
        for name, call in calls.items():
            t = time.perf_counter()
            for _ in range(repeats):
                call()
            best[name] = min(best[name], 1000 * (time.perf_counter() - t) / repeats)
    return best


def draw_times(specs: tuple[str, ...] = ("keydoor-specific", "keydoor_n17-specific", "keydoor_n65-specific"),
               rounds: int = 5, repeats: int = 40) -> dict[str, tuple[int, float]]:
    """Best-of-``rounds`` ms of one MH draw of the critic (the guide's sample: S chains x ``burn_in``
    sweeps from the persistent chains, as in every update), on each maze spec: ``{spec: (N, ms)}``."""
    from hubsgo_ppl.specs import load_model_spec

    out = {}
    for spec in specs:
        critic = SubgoalCritic.from_spec(load_model_spec(spec), seed=0)
        critic._draw()                      # compiles the scan
        best = math.inf
        for _ in range(rounds):
            t = time.perf_counter()
            for _ in range(repeats):
                critic._draw()
            best = min(best, 1000 * (time.perf_counter() - t) / repeats)
        out[spec] = (critic.n, best)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--seeds", type=int, default=3, help="seeds for the learning-budget runs")
    parser.add_argument("--floor", default=None, metavar="SPEC",
                        help="only time an update on this spec, compiled and eager, against a bare TraceGraph_ELBO step and the MH sweeps")
    parser.add_argument("--draws", action="store_true",
                        help="only time one MH draw of the critic (S chains x burn-in sweeps) on the KeyDoor specs, N = 5, 17, 65")
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.draws:
        print(f"torch {torch.__version__}, pyro {pyro.__version__}, 1 thread")
        print("\n| spec | N | ms per draw (best of 5 x 40) |\n|---|---|---|")
        for spec, (n, ms) in draw_times().items():
            print(f"| {spec} | {n} | {ms:.2f} |")
        return
    if args.floor:
        best = pyro_floor(args.floor)
        update = best["critic.update (compiled, default)"]
        print(f"torch {torch.__version__}, pyro {pyro.__version__}, 1 thread, spec {args.floor}, B = 64")
        print("\n| call | ms (best of 5 x 40) | / compiled update |\n|---|---|---|")
        for name, ms in best.items():
            print(f"| {name} | {ms:.2f} | {ms / update:.2f} |")
        return
    print(f"torch {torch.__version__}, pyro {pyro.__version__}, 1 thread")
    print("\n| N | graph edges | ms / update (S=64, burn-in 32) | with Pyro validation on every update | ratio |"
          "\n|---|---|---|---|---|")
    for n in (5, 10, 20, 64):
        repeats = args.repeats if n < 64 else max(5, args.repeats // 2)
        ms = 1000 * time_updates(n, repeats)                       # default: validation on the first update
        ms_always = 1000 * time_updates(n, repeats, "always")
        print(f"| {n} | {sparse_graph(n).num_edges} | {ms:.1f} | {ms_always:.1f} | {ms_always / ms:.2f} |")
    batched, mcmc = sampler_rates()
    print(f"\nsampler, N=10: batched {batched:,.0f} chain-sweeps/s; pyro.infer.MCMC {mcmc:,.0f} sweeps/s ({batched / mcmc:.0f}x)")
    print(f"exact log Z + backward at N=20: {log_z_time():.3f} s")
    print("\nKeyDoor learning budget (updates until > 0.8 mass on the two pair configs; checked every 10):")
    for preset in ("specific", "fully_connected", "independent"):
        budgets = [keydoor_budget(preset, seed=s) for s in range(args.seeds)]
        print(f"  {preset}: {budgets}")


if __name__ == "__main__":
    main()

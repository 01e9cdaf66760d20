"""Small MLPs with explicitly seeded initialisation (no global torch RNG), and the online/target
network pair of the DQN learners (:class:`TargetNetwork`)."""

from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Sequence

import torch
from torch import nn

__all__ = ["mlp", "seeded_init_", "TargetNetwork", "forward", "forward_saved", "backward", "flushing_subnormals"]


def mlp(in_dim: int, hidden: Sequence[int], out_dim: int, generator: torch.Generator) -> nn.Sequential:
    """ReLU MLP whose weights are drawn from ``generator`` (PyTorch's default init uses the global RNG)."""
    layers: list[nn.Module] = []
    last = in_dim
    for h in hidden:
        layers += [nn.Linear(last, h), nn.ReLU()]
        last = h
    layers.append(nn.Linear(last, out_dim))
    net = nn.Sequential(*layers)
    seeded_init_(net, generator)
    return net


@torch.no_grad()
def seeded_init_(module: nn.Module, generator: torch.Generator) -> nn.Module:
    """Kaiming-uniform-like init of every Linear layer (same bounds as torch's default), from ``generator``."""
    for m in module.modules():
        if isinstance(m, nn.Linear):
            bound = 1.0 / math.sqrt(m.in_features)
            m.weight.uniform_(-bound, bound, generator=generator)
            m.bias.uniform_(-bound, bound, generator=generator)
    return module


@contextmanager
def flushing_subnormals() -> Iterator[None]:
    """Subnormal floats read and written as zero inside the block (the CPU's flush-to-zero mode, as
    TensorFlow runs by default), restored to IEEE arithmetic after it.

    The learners' Adam steps run in it: a first moment that decays towards zero passes through the
    subnormal range, where every arithmetic operation costs tens of times more. Flushing changes only
    moments below 1.2e-38, whose contribution to a step (about 1e-34) is below the float32 resolution of
    any weight not itself subnormal; the weights come out the same."""
    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        torch.set_flush_denormal(False)


def _plain_layers(net: nn.Module) -> list[nn.Linear | None]:
    """The layers of an :func:`mlp` (None for a ReLU), or [] for any other module (or one with hooks)."""
    layers = net.__dict__.get("_plain_layers")
    if layers is None:
        mods = list(net) if isinstance(net, nn.Sequential) else []
        plain = bool(mods) and all(type(m) in (nn.Linear, nn.ReLU) for m in mods) and not (
            net._forward_hooks or net._forward_pre_hooks or any(m._forward_hooks or m._forward_pre_hooks for m in mods))
        layers = [m if type(m) is nn.Linear else None for m in mods] if plain else []
        net.__dict__["_plain_layers"] = layers
    return layers


def forward(net: nn.Module, x: torch.Tensor) -> torch.Tensor:
    """``net(x)`` for an :func:`mlp`, the same operations without the modules' call machinery (it runs
    a few times per env step); any other module is called as usual."""
    layers = _plain_layers(net)
    if not layers:
        return net(x)
    for m in layers:
        x = torch.relu(x) if m is None else torch._C._nn.linear(x, m.weight, m.bias)
    return x


def _backward_plain(layers: list[nn.Linear | None]) -> bool:
    """Whether :func:`backward` can differentiate these layers: Linear layers, each but the last
    followed by one ReLU."""
    kinds = [m is not None for m in layers]
    return bool(kinds) and kinds[0] and kinds[-1] and all(kinds[i] != kinds[i + 1] for i in range(len(kinds) - 1))


@torch.no_grad()
def forward_saved(net: nn.Module, x: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]] | None:
    """``net(x)`` for an :func:`mlp` and the input of each of its Linear layers, which :func:`backward`
    needs; None for a module it cannot differentiate (the caller then uses autograd)."""
    layers = _plain_layers(net)
    if not _backward_plain(layers):
        return None
    inputs = []
    for m in layers:
        if m is None:
            x = torch.relu(x)
        else:
            inputs.append(x)
            x = torch._C._nn.linear(x, m.weight, m.bias)
    return x, inputs


@torch.no_grad()
def backward(net: nn.Module, inputs: list[torch.Tensor], grad: torch.Tensor) -> list[torch.Tensor]:
    """The gradient of every parameter of an :func:`mlp` (in ``net.parameters()`` order) given the
    gradient ``grad`` of the loss at its output and the layer inputs :func:`forward_saved` kept.

    These are the operations autograd runs for ``linear`` (``addmm``) and ``relu``, in its order and with
    its operand layouts, so the gradients equal ``loss.backward()``'s to the bit
    (tests/agents/test_nets.py), without building and walking a graph for a small network's step."""
    linears = [m for m in _plain_layers(net) if m is not None]
    grads: list[torch.Tensor] = []
    for i in range(len(linears) - 1, -1, -1):
        m, x = linears[i], inputs[i]
        g_w = grad.t().mm(x)                                        # mm_mat2_backward of weight.t(), transposed back
        g_b = grad.sum([0], keepdim=True).view(m.bias.shape)        # the engine's sum_to of addmm's broadcast bias
        grads += [g_b, g_w]
        if i > 0:
            grad = torch.ops.aten.threshold_backward(grad.mm(m.weight), x, 0)   # mm_mat1_backward, then ReLU's
    return grads[::-1]


class TargetNetwork:
    """An online network, its target copy and the online network's Adam: the plumbing of the DQN
    learners (the high level, the grid low level and HIRO's discrete low level).

    ``make()`` builds one network; it is called twice, online first, so that a seeded ``make`` draws
    the online weights and then the target's (which are then overwritten by the online ones).
    :meth:`step` takes one gradient step on a loss and moves the target ``tau`` of the way towards the
    online network (Polyak averaging, Stable-Baselines3's ``polyak_update``)."""

    def __init__(self, make: Callable[[], nn.Module], lr: float, tau: float, grad_clip: float | None = None):
        self.online = make()
        self.target = make()
        self.target.load_state_dict(self.online.state_dict())
        self.opt = torch.optim.Adam(self.online.parameters(), lr=lr)
        self.tau, self.grad_clip = tau, grad_clip
        self.stacked = False
        self._online_params: tuple[nn.Module, list[torch.Tensor]] | None = None
        self._target_cache: tuple[nn.Module, list[torch.Tensor]] | None = None    # the weights and Adam state are views of a stack of seeds' (agents/stacked.py)
        self._flat: _Flat | None = None

    def step(self, loss: torch.Tensor) -> None:
        """One Adam step on ``loss`` (gradients clipped to norm ``grad_clip`` where given), then Polyak.

        The same arithmetic as ``opt.zero_grad(); loss.backward(); clip_grad_norm_(...); opt.step();
        polyak_update(...)`` with torch's default (single-tensor) Adam, to the bit, in fewer calls
        (tests/agents/test_nets.py compares the two): the weights, the target's weights and Adam's two
        moments are views of one flat buffer each (:class:`_Flat`), so that each elementwise part of the
        step is one operation on the whole network rather than one per parameter."""
        params = self._params()
        for p in params:
            p.grad = None
        loss.backward()
        self.apply([p.grad for p in params])

    @torch.no_grad()
    def apply(self, grads: list[torch.Tensor]) -> None:
        """The rest of :meth:`step` given the gradients of the online parameters (in their order), e.g.
        from :func:`backward`: clipping, Adam, Polyak."""
        params = self._params()
        flat = self._flat_state(params)
        if self.grad_clip is not None:      # nn.utils.clip_grad_norm_ (its foreach path)
            total = torch.linalg.vector_norm(torch.stack(torch._foreach_norm(grads, 2.0)), 2.0)
            coef = torch.clamp(float(self.grad_clip) / (total + 1e-6), max=1.0)
        else:
            coef = None
        if flat is None:
            if coef is not None:
                torch._foreach_mul_(grads, coef)
            self._adam(params, grads)
            targets = self._target_params()     # stable_baselines3's polyak_update
            torch._foreach_mul_(targets, 1 - self.tau)
            torch._foreach_add_(targets, params, alpha=self.tau)
            return
        g = torch.cat([x.reshape(-1) for x in grads])
        if coef is not None:
            g.mul_(coef)
        flat.adam(self.opt.param_groups[0], g)
        flat.target.mul_(1 - self.tau)
        flat.target.add_(flat.params, alpha=self.tau)

    def _flat_state(self, params: list[torch.Tensor]) -> "_Flat | None":
        """The flat buffers the step works on, (re)built where a load or a stacking replaced the tensors
        they hold; None where the step must take the per-parameter path (a stacked network, another
        optimiser, or parameters whose Adam step counts differ)."""
        if self.stacked or not self._plain_adam():
            return None
        flat = self._flat
        if flat is None or not flat.holds(params, self._target_params(), self.opt.state):
            flat = self._flat = _Flat.build(params, self._target_params(), self.opt.state)
        return flat

    def _plain_adam(self) -> bool:
        group = self.opt.param_groups[0]
        return not (type(self.opt) is not torch.optim.Adam or len(self.opt.param_groups) != 1 or group.get("weight_decay")
                    or group.get("amsgrad") or group.get("maximize") or group.get("decoupled_weight_decay"))

    def _params(self) -> list[torch.Tensor]:
        if self._online_params is None or self._online_params[0] is not self.online:
            self._online_params = (self.online, list(self.online.parameters()))
        return self._online_params[1]

    def _target_params(self) -> list[torch.Tensor]:
        if self._target_cache is None or self._target_cache[0] is not self.target:
            self._target_cache = (self.target, list(self.target.parameters()))
        return self._target_cache[1]

    def _adam(self, params: list[torch.Tensor], grads: list[torch.Tensor]) -> None:
        """torch.optim.Adam's step (no weight decay, amsgrad or maximize: the learners' settings), as
        its single-tensor implementation computes it, on the optimiser's own state, parameter by
        parameter (the path of a network whose tensors are not flat)."""
        if not self._plain_adam():
            for p, g in zip(params, grads):
                p.grad = g
            self.opt.step()
            return
        group = self.opt.param_groups[0]
        lr, (beta1, beta2), eps = float(group["lr"]), group["betas"], group["eps"]
        state = self.opt.state
        for p in params:
            if not state[p]:
                _init_adam_state(state, p, torch.zeros_like(p), torch.zeros_like(p))
        sts = [state[p] for p in params]
        steps = [st["step"] for st in sts]
        exp_avgs = [st["exp_avg"] for st in sts]
        exp_avg_sqs = [st["exp_avg_sq"] for st in sts]
        torch._foreach_add_(steps, 1)
        step = [float(t.item()) for t in steps]
        step_size = [-(lr / (1 - beta1 ** n)) for n in step]
        bc2_sqrt = [(1 - beta2 ** n) ** 0.5 for n in step]
        with flushing_subnormals():
            torch._foreach_lerp_(exp_avgs, grads, 1 - beta1)
            torch._foreach_mul_(exp_avg_sqs, beta2)
            torch._foreach_addcmul_(exp_avg_sqs, grads, grads, 1 - beta2)
            denom = torch._foreach_sqrt(exp_avg_sqs)
            torch._foreach_div_(denom, bc2_sqrt)
            torch._foreach_add_(denom, eps)
            torch._foreach_addcdiv_(params, exp_avgs, denom, step_size)

    def state_dict(self, online: str = "q", target: str = "q_target", opt: str = "opt") -> dict[str, Any]:
        """The three states under the names a learner's checkpoint uses (copies of a stacked network's
        slices, so that a checkpoint holds only its own seed)."""
        s = {online: self.online.state_dict(), target: self.target.state_dict(), opt: self.opt.state_dict()}
        if self.stacked:
            s = _cloned(s)
        return s

    def load_state_dict(self, s: dict[str, Any], online: str = "q", target: str = "q_target", opt: str = "opt") -> None:
        self.online.load_state_dict(s[online])
        self.target.load_state_dict(s[target])
        self.opt.load_state_dict(s[opt])


def _cloned(x: Any) -> Any:
    """``x`` with every tensor in its dicts and lists copied."""
    if isinstance(x, torch.Tensor):
        return x.clone()
    if isinstance(x, dict):
        out = type(x)((k, _cloned(v)) for k, v in x.items())
        if hasattr(x, "_metadata"):     # a module's state_dict: its layout versions
            out._metadata = x._metadata
        return out
    if isinstance(x, list):
        return [_cloned(v) for v in x]
    return x


def _init_adam_state(state: dict, p: torch.Tensor, exp_avg: torch.Tensor, exp_avg_sq: torch.Tensor) -> None:
    """torch.optim.Adam's state of ``p`` before its first step, with the given (zero) moment tensors."""
    state[p]["step"] = torch.tensor(0.0, dtype=torch.float32)
    state[p]["exp_avg"] = exp_avg
    state[p]["exp_avg_sq"] = exp_avg_sq


class _Flat:
    """A network's weights, its target's weights and Adam's two moments, each one flat buffer whose
    slices are the parameters, the target's parameters and the optimiser's state tensors (views), so that
    Adam and Polyak run as one elementwise operation each. Elementwise arithmetic does not depend on
    where a number sits in a buffer, so the results equal the per-parameter ones to the bit."""

    def __init__(self, params: list[torch.Tensor], targets: list[torch.Tensor], state: dict):
        self.params = torch.cat([p.detach().reshape(-1) for p in params])
        self.target = torch.cat([t.detach().reshape(-1) for t in targets])
        fresh = not state[params[0]]
        self.exp_avg = torch.zeros_like(self.params) if fresh else torch.cat([state[p]["exp_avg"].reshape(-1) for p in params])
        self.exp_avg_sq = torch.zeros_like(self.params) if fresh else torch.cat([state[p]["exp_avg_sq"].reshape(-1) for p in params])
        offset = 0
        for p, t in zip(params, targets):
            n = p.numel()
            sl = slice(offset, offset + n)
            p.data = self.params[sl].view_as(p)
            t.data = self.target[sl].view_as(t)
            if fresh:
                _init_adam_state(state, p, self.exp_avg[sl].view_as(p), self.exp_avg_sq[sl].view_as(p))
            else:
                state[p]["exp_avg"] = self.exp_avg[sl].view_as(p)
                state[p]["exp_avg_sq"] = self.exp_avg_sq[sl].view_as(p)
            offset += n
        self.steps = [state[p]["step"] for p in params]
        self._held = [(p, p.data_ptr(), t, t.data_ptr(), state[p]) for p, t in zip(params, targets)]
        self._views = [(st["step"], st["exp_avg"], st["exp_avg_sq"]) for *_, st in self._held]

    @classmethod
    def build(cls, params: list[torch.Tensor], targets: list[torch.Tensor], state: dict) -> "_Flat | None":
        """The flat buffers of a network whose parameters share one dtype and device and one Adam step
        count (None otherwise: the per-parameter path then takes the step)."""
        kinds = {(p.dtype, p.device) for p in [*params, *targets]}
        started = [bool(state[p]) for p in params]
        if len(kinds) != 1 or len(params) != len(targets) or len(set(started)) != 1:
            return None
        if started[0] and len({float(state[p]["step"]) for p in params}) != 1:
            return None
        return cls(params, targets, state)

    def holds(self, params: list[torch.Tensor], targets: list[torch.Tensor], state: dict) -> bool:
        """Whether the parameters and the optimiser's state are still the views this buffer made (a load
        of the optimiser's state, or stacking, replaces them)."""
        if len(params) != len(self._held):
            return False
        for (p, ptr, t, tptr, st), p2, t2, (step, m, v) in zip(self._held, params, targets, self._views):
            if p is not p2 or t is not t2 or p.data_ptr() != ptr or t.data_ptr() != tptr or state.get(p) is not st \
                    or st.get("step") is not step or st.get("exp_avg") is not m or st.get("exp_avg_sq") is not v:
                return False
        return True

    def adam(self, group: dict, g: torch.Tensor) -> None:
        """torch.optim.Adam's single-tensor step on the flat gradient ``g``."""
        lr, (beta1, beta2), eps = float(group["lr"]), group["betas"], group["eps"]
        torch._foreach_add_(self.steps, 1)
        n = float(self.steps[0].item())
        with flushing_subnormals():
            self.exp_avg.lerp_(g, 1 - beta1)
            self.exp_avg_sq.mul_(beta2)
            self.exp_avg_sq.addcmul_(g, g, value=1 - beta2)
            denom = self.exp_avg_sq.sqrt()
            denom.div_((1 - beta2 ** n) ** 0.5)
            denom.add_(eps)
            self.params.addcdiv_(self.exp_avg, denom, value=-(lr / (1 - beta1 ** n)))

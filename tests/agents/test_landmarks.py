"""HIGL's landmark parts against hand-computed cases: farthest-point sampling, visit counts, shortest
paths with a cutoff, the landmark selection, the pseudo-landmark and the landmark loss's gradient."""

import math

import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.landmarks import (NoveltyCounts, farthest_point_sampling, landmark_loss, pseudo_landmark,
                                         select_landmark, shortest_paths)
from hubsgo_ppl.agents.td3 import TD3Core

INF = math.inf


def test_farthest_point_sampling_on_a_small_point_set():
    pts = np.array([[0, 0], [1, 0], [5, 0], [0, 4], [1, 1]], float)
    # from (0,0): distances 1, 5, 4, √2 -> (5,0); then min distances 1, 0, 4, √2 -> (0,4); then 1, 0, 0, √2 -> (1,1)
    assert farthest_point_sampling(pts, 3).tolist() == [0, 2, 3]
    assert farthest_point_sampling(pts, 4).tolist() == [0, 2, 3, 4]
    # duplicates are never chosen twice: it stops when every point is covered
    assert farthest_point_sampling(np.array([[0, 0], [0, 0], [2, 0], [2, 0]]), 5).tolist() == [0, 2]
    assert farthest_point_sampling(np.zeros((0, 2)), 3).tolist() == []


def test_novelty_counts_cells_and_returns_the_least_visited_first_seen_states():
    nov = NoveltyCounts(cell=1.0, obs_dim=1, goal_dim=2)
    for i, ag in enumerate([(0, 0), (1, 0), (0, 0), (0.4, -0.3), (2, 2), (1, 0)]):
        nov.visit(np.array([float(i)]), np.array(ag, float))
    assert len(nov) == 3
    assert [nov.count(np.array(a, float)) for a in [(0, 0), (1, 0), (2, 2), (5, 5)]] == [3, 2, 1, 0]
    assert nov.novelty(np.array([0.0, 0.0])) == pytest.approx(1 / math.sqrt(3))
    assert nov.novelty(np.array([5.0, 5.0])) == 1.0
    obs, ag = nov.most_novel(2)
    assert ag.tolist() == [[2, 2], [1, 0]] and obs[:, 0].tolist() == [4.0, 1.0]    # first-seen states
    restored = NoveltyCounts(cell=1.0, obs_dim=1, goal_dim=2)
    restored.load_state_dict(nov.state_dict())
    assert restored.count(np.array([0.1, 0.2])) == 3 and restored.most_novel(3)[1].tolist() == \
        nov.most_novel(3)[1].tolist()
    coarse = NoveltyCounts(cell=0.05, obs_dim=1, goal_dim=1)
    coarse.visit(np.zeros(1), np.array([0.11]))
    assert coarse.count(np.array([0.09])) == 1 and coarse.count(np.array([0.13])) == 0     # 0.10 ± 0.025


def test_shortest_paths_on_a_hand_built_graph_with_a_cutoff():
    d = np.full((4, 4), INF)
    d[0, 1], d[1, 2], d[0, 2], d[2, 3], d[0, 3] = 1.0, 2.0, 2.5, 1.0, 10.0
    assert shortest_paths(d, cutoff=100)[0, 3] == 3.5              # 0 -> 2 -> 3
    D = shortest_paths(d, cutoff=2.2)                               # drops 0 -> 2 and 0 -> 3
    assert D[0, 3] == 4.0 and D[0, 2] == 3.0 and D[1, 3] == 3.0 and D[3, 0] == INF
    assert np.all(np.diag(D) == 0)
    assert shortest_paths(d, cutoff=1.5)[0, 3] == INF               # 1 -> 2 cut as well: no way left


def test_select_landmark_takes_the_shortest_way_through_a_landmark_or_the_target():
    to_target = np.array([4.0, 1.0])                # two landmarks' shortest ways to the target (node 2)
    d_cur = np.array([[1.0, 3.0, 10.0],             # through 0: 5, through 1: 4, direct: cut -> landmark 1
                      [1.0, 3.0, 4.0],              # direct 4 ties the best landmark: the target
                      [9.0, 9.0, 9.0],              # nothing within the cutoff: the target
                      [0.5, 6.0, 6.0]])             # landmark 1 beyond the cutoff: 0.5 + 4 -> landmark 0
    assert select_landmark(d_cur, to_target, cutoff=5.0).tolist() == [1, 2, 2, 0]


def test_pseudo_landmark_is_at_most_a_step_towards_the_landmark():
    ag = torch.tensor([[0.0, 0.0], [1.0, 1.0]])
    lm = torch.tensor([[3.0, 4.0], [1.5, 1.0]])
    torch.testing.assert_close(pseudo_landmark(ag, lm, 1.0), torch.tensor([[0.6, 0.8], [1.5, 1.0]]))
    torch.testing.assert_close(pseudo_landmark(ag, ag, 1.0), ag)


def test_landmark_loss_gradient_points_the_goal_towards_the_landmark():
    goal = torch.tensor([[1.0, 0.0]], requires_grad=True)
    ag, target, scale = torch.tensor([[0.0, 0.0]]), torch.tensor([[0.0, 2.0]]), torch.tensor([2.0, 2.0])
    loss = landmark_loss(goal, ag, target, scale)
    assert loss.item() == pytest.approx(math.sqrt(5) / 2)
    loss.backward()
    # d/dg ||(g - t)/s|| = (g - t) / (s^2 ||(g - t)/s||) = (1, -2) / (4 * √5 / 2)
    torch.testing.assert_close(goal.grad, torch.tensor([[1.0, -2.0]]) / (2 * math.sqrt(5)))
    step = goal.detach() - 0.1 * goal.grad
    assert (step - target).norm() < (goal.detach() - target).norm()


def test_td3_actor_extra_pulls_the_actor_towards_the_landmark():
    """Through the shared TD3 core: with a heavy landmark term the actor's goal moves to the target."""
    def core():
        return TD3Core(3, 2, (16,), torch.Generator().manual_seed(0), actor_lr=1e-2, critic_lr=1e-3, tau=0.005,
                       policy_delay=1, target_noise=0.2, target_noise_clip=0.5, scale=np.array([2.0, 2.0]))

    x, a = torch.rand(32, 3, generator=torch.Generator().manual_seed(1)), torch.zeros(32, 2)
    target = torch.tensor([1.5, -1.0]).expand(32, 2)
    plain, guided = core(), core()
    before = (guided.mu(x) - target).norm(dim=-1).mean().item()
    for _ in range(60):
        plain.update(x, a, torch.zeros(32), x, 0.0, torch.zeros(32, 2))
        guided.update(x, a, torch.zeros(32), x, 0.0, torch.zeros(32, 2),
                      actor_extra=lambda pi: 100.0 * landmark_loss(pi, torch.zeros(32, 2), target, torch.tensor(2.0)))
    after = (guided.mu(x) - target).norm(dim=-1).mean().item()
    assert after < 0.2 * before and (plain.mu(x) - target).norm(dim=-1).mean().item() > 0.5 * before

import itertools
import math

import numpy as np
import pytest
import torch
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from arm_training.reconstruction.losses.connectivity_prior import (
    V_MIN,
    cheapest_path_costs,
    coarsen_occupancy,
    connectivity_log_probability,
    connectivity_loss,
    connectivity_value_and_gradient,
)

D = 32


def _node_weighted_dijkstra(node_cost):
    """All-pairs cheapest 26-connected path costs, both ends included, with scipy."""
    shape = node_cost.shape
    n = node_cost.size
    rows, cols, weights = [], [], []
    for index in range(n):
        x, y, z = np.unravel_index(index, shape)
        for dx, dy, dz in itertools.product((-1, 0, 1), repeat=3):
            nx, ny, nz = x + dx, y + dy, z + dz
            if (dx, dy, dz) != (0, 0, 0) and 0 <= nx < shape[0] and 0 <= ny < shape[1] and 0 <= nz < shape[2]:
                rows.append(index)
                cols.append(np.ravel_multi_index((nx, ny, nz), shape))
                weights.append(node_cost[nx, ny, nz] + 1e-12)
    graph = csr_matrix((weights, (rows, cols)), shape=(n, n))
    return dijkstra(graph, directed=True) + node_cost.reshape(-1)[:, None]


def test_cheapest_path_costs_match_dijkstra():
    rng = np.random.default_rng(0)
    node_cost = rng.exponential(2.0, (5, 4, 6))
    reference = _node_weighted_dijkstra(node_cost)
    sources = torch.tensor([[0, 17, 63, 119]])
    costs = cheapest_path_costs(torch.tensor(node_cost)[None], sources)
    np.testing.assert_allclose(costs[0].numpy(), reference[sources[0].numpy()], rtol=1e-6)


def _naive_reference(v_cells):
    """Appendix-B value and gradient with explicit loops over pairs and cells (factor 1)."""
    v = np.clip(v_cells, V_MIN, 1 - V_MIN).reshape(-1)
    cost = -np.log(v)
    dist = _node_weighted_dijkstra(cost.reshape(v_cells.shape))
    existing = np.flatnonzero(v >= 0.5)
    pairs = list(itertools.combinations(existing, 2))
    value, grad = 0.0, np.zeros(v.size)
    for a, b in pairs:
        p_star = math.exp(-(dist[a, b] - cost[a] - cost[b]))
        vv = v[a] * v[b]
        value += math.log(vv * p_star + 1 - vv)
        for c in range(v.size):
            if c in (a, b):
                continue
            through_c = dist[a, c] + dist[c, b] - cost[c]
            p_c = math.exp(-(through_c - cost[a] - cost[b]))
            if through_c <= dist[a, b] * (1 + 1e-9) + 1e-9:
                q, dq = p_star, p_star / v[c]
            else:
                q, dq = 1 - (1 - p_star) * (1 - p_c), (1 - p_star) * p_c / v[c]
            grad[c] += vv * dq / (vv * q + 1 - vv)
    return value / len(pairs), grad.reshape(v_cells.shape) / len(pairs)


def test_vectorized_matches_the_appendix_formula_on_a_small_grid():
    rng = np.random.default_rng(1)
    v_cells = rng.uniform(0.02, 0.98, (4, 4, 3))
    ref_value, ref_grad = _naive_reference(v_cells)
    logits = torch.logit(torch.tensor(v_cells, dtype=torch.float64)).float()[None]
    value, grad = connectivity_value_and_gradient(logits, factor=1, max_endpoints=48)
    assert value.item() == pytest.approx(ref_value, rel=1e-4)
    np.testing.assert_allclose(grad[0].double().numpy(), ref_grad, rtol=2e-3, atol=1e-7)


def _two_blobs(gap_logit=-4.0):
    occupancy = torch.zeros(1, D, D, D)
    occupancy[:, 12:20, 12:20, 2:8] = 1
    occupancy[:, 12:20, 12:20, 16:24] = 1
    logits = torch.where(occupancy > 0, torch.tensor(6.0), torch.tensor(gap_logit)).requires_grad_(True)
    unobserved = occupancy == 0
    return occupancy, logits, unobserved


def test_gap_between_observed_blobs_is_raised_along_the_most_likely_path():
    occupancy, logits, unobserved = _two_blobs()
    connectivity_loss(logits, unobserved, factor=2).backward()
    grad = logits.grad[0]
    gap = grad[12:20, 12:20, 8:16]
    assert (gap < 0).all(), "the loss decreases when gap voxels become more likely"
    assert (grad[occupancy[0] > 0] == 0).all(), "observed voxels get no gradient"
    assert (grad <= 0).all(), "the connectivity prior only adds connections"
    away = grad[0:6, 0:6, 8:16]
    assert gap.abs().min() > 1e3 * away.abs().max()


def test_more_likely_detour_is_preferred_over_the_shortest_path():
    occupancy, logits, unobserved = _two_blobs(gap_logit=-8.0)
    with torch.no_grad():
        logits[0, 20:24, 12:20, 8:16] = -1.0  # a likelier corridor beside the straight gap
    connectivity_loss(logits, unobserved, factor=2).backward()
    grad = logits.grad[0]
    corridor = grad[20:24, 12:20, 8:16].abs().mean()
    straight = grad[12:20, 12:20, 10:14].abs().mean()
    assert corridor > 10 * straight


def test_connected_object_has_high_connectivity_and_gap_lowers_it():
    occupancy, logits, unobserved = _two_blobs()
    connected = logits.detach().clone()
    connected[0, 12:20, 12:20, 8:16] = 6.0
    gap_value = connectivity_log_probability(logits.detach(), unobserved)
    connected_value = connectivity_log_probability(connected, unobserved)
    assert connected_value.item() > -0.05
    assert gap_value.item() < -1.0


def test_gradient_goes_through_sigmoid_mask_and_grad_output():
    rng = np.random.default_rng(2)
    logits = torch.tensor(rng.normal(0.0, 3.0, (2, 8, 8, 8)), dtype=torch.float32)
    unobserved = torch.tensor(rng.random((2, 8, 8, 8)) > 0.5)
    _, grad_v = connectivity_value_and_gradient(logits, factor=2, max_endpoints=64)
    sigmoid = torch.sigmoid(logits)
    weights = torch.tensor([2.0, -0.25])
    leaf = logits.clone().requires_grad_(True)
    (connectivity_log_probability(leaf, unobserved, factor=2, max_endpoints=64) * weights).sum().backward()
    expected = grad_v * sigmoid * (1 - sigmoid) * unobserved * weights.view(-1, 1, 1, 1)
    torch.testing.assert_close(leaf.grad, expected)


def test_finite_for_extreme_logits():
    logits = torch.full((3, 16, 16, 16), -90.0)
    logits[0, 2:4, 2:4, 2:4] = 90.0
    logits[0, 12:14, 12:14, 12:14] = 90.0
    logits[1] = torch.randn(16, 16, 16) * 40.0
    logits = logits.requires_grad_(True)
    value = connectivity_log_probability(logits, torch.ones(3, 16, 16, 16, dtype=torch.bool))
    (-value.sum()).backward()
    assert torch.isfinite(value).all() and torch.isfinite(logits.grad).all()
    assert value[2].item() == 0.0 and logits.grad[2].abs().max() == 0


def test_endpoint_sampling_is_reproducible_and_coarsening_checks_shape():
    logits = torch.randn(2, 16, 16, 16) * 4.0
    first = connectivity_value_and_gradient(logits, generator=torch.Generator().manual_seed(4))
    second = connectivity_value_and_gradient(logits, generator=torch.Generator().manual_seed(4))
    torch.testing.assert_close(first[1], second[1])
    with pytest.raises(ValueError):
        coarsen_occupancy(torch.rand(1, 10, 10, 10), 4)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu():
    occupancy, logits, unobserved = _two_blobs()
    value_cpu, grad_cpu = connectivity_value_and_gradient(logits.detach(), max_endpoints=512)
    value_gpu, grad_gpu = connectivity_value_and_gradient(logits.detach().cuda(), max_endpoints=512)
    torch.testing.assert_close(value_gpu.cpu(), value_cpu, rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(grad_gpu.cpu(), grad_cpu, rtol=1e-3, atol=1e-9)

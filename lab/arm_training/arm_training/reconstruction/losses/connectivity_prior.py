"""Connectivity prior P(C(v)) of ARM (paper Sec. 3.2, appendix B) with its approximate gradient.

The occupancy ``V = sigmoid(logits)`` (``[B, X, Y, Z]``) is coarsened by ``factor`` (a coarse cell
exists when its most likely voxel does: max pooling) to a 26-connected grid graph. A path ``t``
exists with probability ``P(t) = prod_{i in t} V(i)``; for two existing cells ``a, b``

    P(C(v)) = prod_{a != b} [V(a) V(b) P(C(a, b)) + 1 - V(a) V(b)]

where ``P(C(a, b))`` is the probability that the cells strictly between them on some path exist.
For a cell ``c`` the union over paths is approximated by ``t*`` (the most likely ``a``-``b`` path)
and ``t^c`` (the most likely one through ``c``):

    P(C(a, b)) ~ Q_abc = P(t*)                          if c on t*
                         1 - (1 - P(t*)) (1 - P(t^c))   otherwise
    dQ_abc / dV(c)     = P(t^c) / V(c) * (1 if c on t* else 1 - P(t*))
    d log P(C) / dV(c) = sum_{a != b != c} V(a) V(b) dQ_abc/dV(c) / (V(a) V(b) Q_abc + 1 - V(a) V(b))

which is positive: the prior only strengthens likely connections (terms with ``c`` as an endpoint
are left out, as in the paper). All path probabilities are computed as shortest paths on the node
costs ``-log V`` (the most likely path is the cheapest one); ``P(t^c) / V(c)`` is the product of
``V`` over the path without ``a``, ``b`` and ``c``, so no division by small ``V`` happens.

Endpoints ``a, b`` are the existing cells (``V >= 0.5``), at most ``max_endpoints`` of them (the most
likely); every cell is an intermediate node. The cheapest paths from all endpoints to all cells are
found at once by a multi-source Bellman-Ford on the grid (min-pooling relaxation, exact at
convergence), and the ``[K, K, N]`` endpoint-pair x cell terms are evaluated as tensors. The value
and the gradient are averaged over endpoint pairs so that the loss weight does not scale with the
object size. The off-path term rewards any cell that offers a detour between two existing cells
(a second path raises P(t* or t^c)), so next to a moderately confident shape it pushes the
unobserved neighbours up: the prior inflates shapes unless its weight is small against the
reconstruction loss (measured in training: weight 1e-2 diverged, 1e-4 did not).
The cell gradient reaches every voxel of the cell (a cell exists when any of its
voxels does), then goes through the sigmoid, the F4 mask (unobserved voxels) and ``grad_output``.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

V_MIN = 1e-6


def coarsen_occupancy(occupancy: torch.Tensor, factor: int) -> torch.Tensor:
    """Max-pool ``[B, X, Y, Z]`` occupancy by ``factor`` (each size must be divisible by it)."""
    if any(size % factor for size in occupancy.shape[1:]):
        raise ValueError(f"grid shape {tuple(occupancy.shape[1:])} is not divisible by factor {factor}")
    return F.max_pool3d(occupancy.unsqueeze(1), factor).squeeze(1)


def _min_pool_26(costs: torch.Tensor) -> torch.Tensor:
    """Minimum over each cell's 3x3x3 neighbourhood, ``costs`` is ``[M, X, Y, Z]``.

    Separable: a 3-wide minimum along each axis in turn (in place on contiguous slices, the fastest
    form on CPU).
    """
    result = costs.clone()
    for dim in (1, 2, 3):
        before = result.clone()
        length = result.shape[dim] - 1
        upper = result.narrow(dim, 1, length)
        upper.copy_(torch.minimum(upper, before.narrow(dim, 0, length)))
        lower = result.narrow(dim, 0, length)
        lower.copy_(torch.minimum(lower, before.narrow(dim, 1, length)))
    return result


def cheapest_path_costs(node_cost: torch.Tensor, sources: torch.Tensor, check_every: int = 4) -> torch.Tensor:
    """Cost of the cheapest 26-connected path from each source to every cell, both ends included.

    ``node_cost``: ``[B, X, Y, Z]`` non-negative (``-log V``). ``sources``: ``[B, K]`` flat cell
    indices. Returns ``[B, K, X*Y*Z]``. Bellman-Ford relaxations of all sources at once until no cost
    changes (at most ``X*Y*Z`` rounds, the longest simple path).
    """
    batch, size_x, size_y, size_z = node_cost.shape
    n_cells = size_x * size_y * size_z
    n_sources = sources.shape[1]
    flat_cost = node_cost.reshape(batch, 1, n_cells).expand(-1, n_sources, -1)
    costs = torch.full((batch, n_sources, n_cells), float("inf"), device=node_cost.device, dtype=node_cost.dtype)
    costs.scatter_(2, sources.unsqueeze(2), torch.gather(flat_cost, 2, sources.unsqueeze(2)))
    grid_shape = (batch * n_sources, size_x, size_y, size_z)
    step_cost = flat_cost.reshape(grid_shape)
    costs = costs.reshape(grid_shape)
    for round_index in range(n_cells):
        relaxed = torch.minimum(costs, _min_pool_26(costs) + step_cost)
        if (round_index + 1) % check_every == 0 and torch.equal(relaxed, costs):
            break
        costs = relaxed
    return costs.reshape(batch, n_sources, n_cells)


def select_endpoints(
    cell_occupancy: torch.Tensor, max_endpoints: int, generator: torch.Generator | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Endpoint cells ``[B, K]`` and whether each exists (``V >= 0.5``).

    All existing cells when there are at most ``max_endpoints``, otherwise a uniform random sample of
    them (the pair average is then an unbiased estimate). Padding entries are marked not existing.
    """
    flat = cell_occupancy.flatten(1)
    exists = flat >= 0.5
    noise = torch.rand(flat.shape, device=flat.device, generator=generator)
    count = min(max_endpoints, flat.shape[1])
    index = torch.topk(exists.float() + 0.5 * noise, count, dim=1).indices
    return index, exists.gather(1, index)


def _box_around_existing(cells: torch.Tensor, margin_cells: int) -> tuple[slice, slice, slice]:
    existing = (cells >= 0.5).any(dim=0).nonzero()
    if len(existing) == 0:
        return (slice(None),) * 3
    lo = (existing.min(dim=0).values - margin_cells).clamp_min(0).tolist()
    hi = (existing.max(dim=0).values + margin_cells + 1).tolist()
    return tuple(slice(a, min(b, size)) for a, b, size in zip(lo, hi, cells.shape[1:], strict=True))


def connectivity_value_and_gradient(
    logits: torch.Tensor,
    factor: int = 2,
    max_endpoints: int = 16,
    with_gradient: bool = True,
    on_path_tolerance: float = 1e-4,
    generator: torch.Generator | None = None,
    margin_cells: int = 2,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Pair-averaged ``log P(C(v))`` ``[B]`` and the appendix-B ``d/dV`` ``[B, X, Y, Z]`` (unmasked).

    Paths are searched in the box around the batch's existing cells widened by ``margin_cells``
    (the most likely paths between existing cells stay near them); cells outside get no gradient.
    """
    with torch.no_grad():
        v = torch.sigmoid(logits.float())
        all_cells = coarsen_occupancy(v, factor).clamp(V_MIN, 1.0 - V_MIN)
        box = _box_around_existing(all_cells, margin_cells)
        cells = all_cells[(slice(None), *box)].contiguous()
        node_cost = -torch.log(cells).flatten(1)
        endpoints, exists = select_endpoints(cells, max_endpoints, generator)
        cost_from = cheapest_path_costs(node_cost.view_as(cells), endpoints)
        first, second = torch.triu_indices(endpoints.shape[1], endpoints.shape[1], offset=1, device=logits.device)
        pair_valid = exists[:, first] & exists[:, second]
        n_pairs = pair_valid.sum(dim=1).clamp_min(1).float()
        cost_a, cost_b = cost_from[:, first], cost_from[:, second]
        end_cost = node_cost.gather(1, endpoints)
        end_cost_a, end_cost_b = end_cost[:, first, None], end_cost[:, second, None]
        ab_cost = cost_a.gather(2, endpoints[:, second, None])
        p_star = torch.exp(-(ab_cost - end_cost_a - end_cost_b).clamp_min(0.0))
        end_v = cells.flatten(1).gather(1, endpoints)
        vv = (end_v[:, first] * end_v[:, second]).unsqueeze(2)
        pair_log = torch.log(vv * p_star + 1.0 - vv).squeeze(2)
        value = torch.where(pair_valid, pair_log, torch.zeros_like(pair_log)).sum(dim=1) / n_pairs
        if not with_gradient:
            return value, None

        cell_cost = node_cost.unsqueeze(1)
        # P(t^c) / V(c): the cells strictly between a and c times those strictly between c and b
        log_p_c_over_v_c = -(cost_a - end_cost_a - cell_cost).clamp_min(0.0) - (
            cost_b - end_cost_b - cell_cost
        ).clamp_min(0.0)
        p_c_over_v_c = torch.exp(log_p_c_over_v_c)
        p_c = p_c_over_v_c * torch.exp(-cell_cost)
        on_path = cost_a + cost_b - cell_cost <= ab_cost * (1.0 + on_path_tolerance) + on_path_tolerance
        q = torch.where(on_path, p_star, 1.0 - (1.0 - p_star) * (1.0 - p_c))
        dq = p_c_over_v_c * torch.where(on_path, torch.ones_like(q), 1.0 - p_star)
        term = vv * dq / (vv * q + 1.0 - vv)
        cell_ids = torch.arange(node_cost.shape[1], device=logits.device)
        is_endpoint = (endpoints[:, first, None] == cell_ids) | (endpoints[:, second, None] == cell_ids)
        keep = pair_valid.unsqueeze(2) & ~is_endpoint
        # each unordered pair stands for (a, b) and (b, a): twice the terms over twice the pairs
        cell_gradient = torch.where(keep, term, torch.zeros_like(term)).sum(dim=1) / n_pairs[:, None]
        spread = torch.zeros_like(all_cells)
        spread[(slice(None), *box)] = cell_gradient.view_as(cells)
        for axis in (1, 2, 3):
            spread = spread.repeat_interleave(factor, dim=axis)
    return value, spread


class ConnectivityLogProbability(torch.autograd.Function):
    """Pair-averaged ``log P(C(v))`` per batch item ``[B]`` from logits, with the appendix-B gradient."""

    @staticmethod
    def forward(ctx, logits, unobserved_mask, factor, max_endpoints, generator):
        with_gradient = ctx.needs_input_grad[0]
        value, grad_v = connectivity_value_and_gradient(
            logits, factor, max_endpoints, with_gradient, generator=generator
        )
        if with_gradient:
            v = torch.sigmoid(logits.float())
            ctx.save_for_backward(grad_v * v * (1.0 - v) * unobserved_mask.float())
        return value.to(logits.dtype)

    @staticmethod
    def backward(ctx, grad_output):
        (grad_logits,) = ctx.saved_tensors
        scaled = grad_logits * grad_output.float().view(-1, 1, 1, 1)
        return scaled.to(grad_output.dtype), None, None, None, None


def connectivity_log_probability(
    logits: torch.Tensor,
    unobserved_mask: torch.Tensor,
    factor: int = 2,
    max_endpoints: int = 16,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Pair-averaged ``log P(C(v))`` ``[B]``; its backward is the appendix-B approximate gradient.

    ``logits``: ``[B, X, Y, Z]``; ``unobserved_mask``: F4, the only voxels that get a gradient.
    """
    return ConnectivityLogProbability.apply(logits, unobserved_mask, factor, max_endpoints, generator)


def connectivity_loss(logits, unobserved_mask, factor: int = 2, max_endpoints: int = 16) -> torch.Tensor:
    """Scalar loss ``-mean_b log P(C(v_b))``."""
    return -connectivity_log_probability(logits, unobserved_mask, factor, max_endpoints).mean()

import math

import numpy as np
import pytest
import torch
from scipy.special import ndtr

from arm_training.reconstruction.losses.stability_prior import (
    stability_log_probability,
    stability_loss,
    stability_value_and_gradient,
)

D = 24


def _block(grid, xs, ys, zs, value=1.0):
    grid[:, xs[0] : xs[1], ys[0] : ys[1], zs[0] : zs[1]] = value
    return grid


def _scene(occupancy, observed=None):
    """Logits from a 0/1 occupancy; unobserved = everything not in ``observed`` (default: the object)."""
    logits = torch.where(occupancy > 0, torch.tensor(6.0), torch.tensor(-5.0)).requires_grad_(True)
    observed = occupancy > 0 if observed is None else observed
    return logits, ~observed


def _loss_gradient(logits, other, unobserved):
    logits.grad = None
    stability_loss(logits, other, unobserved).backward()
    return logits.grad.detach()


def test_floating_object_gets_gradient_raising_occluded_support():
    occupancy = _block(torch.zeros(1, D, D, D), (8, 14), (8, 14), (8, 14))
    logits, unobserved = _scene(occupancy)
    grad = _loss_gradient(logits, torch.zeros_like(occupancy), unobserved)[0]
    table_layer = grad[:, :, 0]
    assert (table_layer < 0).all(), "every table-level voxel would hold the object: its logit must rise"
    assert table_layer.abs().min() > 1e-4
    assert grad[:, :, 1:].abs().max() == 0, "voxels with nothing below or beside cannot support it"
    assert (grad[occupancy[0] > 0] == 0).all(), "observed voxels get no gradient"


def test_supported_object_gets_about_zero_gradient():
    floating = _block(torch.zeros(1, D, D, D), (8, 14), (8, 14), (8, 14))
    resting = _block(torch.zeros(1, D, D, D), (8, 14), (8, 14), (0, 6))
    logits_f, unobserved_f = _scene(floating)
    logits_r, unobserved_r = _scene(resting)
    grad_f = _loss_gradient(logits_f, torch.zeros_like(floating), unobserved_f)
    grad_r = _loss_gradient(logits_r, torch.zeros_like(resting), unobserved_r)
    assert grad_r.abs().max() < 1e-6 * grad_f.abs().max()
    value = stability_log_probability(logits_r.detach(), torch.zeros_like(resting), unobserved_r)
    assert value.item() > -1e-3


def test_object_resting_on_another_object_is_supported():
    other = _block(torch.zeros(1, D, D, D), (4, 20), (4, 20), (0, 8))
    on_top = _block(torch.zeros(1, D, D, D), (8, 14), (8, 14), (8, 14))
    floating = _block(torch.zeros(1, D, D, D), (8, 14), (8, 14), (10, 16))
    logits_t, unobserved_t = _scene(on_top)
    logits_f, unobserved_f = _scene(floating)
    grad_t = _loss_gradient(logits_t, other, unobserved_t)
    grad_f = _loss_gradient(logits_f, other, unobserved_f)
    assert grad_t.abs().max() < 1e-6 * grad_f.abs().max()
    supports = grad_f[0, 4:20, 4:20, 8]
    assert (supports < 0).all(), "voxels resting on the other object would hold the floating one"


def test_object_leaning_against_a_wall_is_supported_from_beside():
    wall = _block(torch.zeros(1, D, D, D), (14, 16), (0, D), (0, D))
    leaning = _block(torch.zeros(1, D, D, D), (8, 14), (8, 14), (6, 12))
    logits, unobserved = _scene(leaning)
    grad = _loss_gradient(logits, wall, unobserved)[0]
    # directions towards the wall are held by the leaning contact, the others are not: some gradient
    # remains but never on the wall side of the centre of mass
    assert grad[13, 8:14, 6:12].abs().max() == 0  # observed contact column
    assert (grad[:, :, 0] < 0).any()
    no_wall = _loss_gradient(_scene(leaning)[0], torch.zeros_like(wall), unobserved)[0]
    assert grad.abs().sum() < no_wall.abs().sum()


def test_overhang_raises_support_under_the_overhang_only():
    body = torch.zeros(1, D, D, D)
    _block(body, (2, 5), (10, 14), (0, 12))  # column on the table
    _block(body, (2, 22), (10, 14), (12, 15))  # long arm over +x: centre of mass beyond the column
    logits, unobserved = _scene(body)
    grad = _loss_gradient(logits, torch.zeros_like(body), unobserved)[0]
    under_overhang = grad[16:22, 10:14, 0]
    behind_column = grad[0:2, 10:14, 0]
    assert (under_overhang < -1e-3).all()
    assert behind_column.abs().max() < 1e-3 * under_overhang.abs().min()


def _naive_reference(logits, other, sigma_floor=0.25, n_dirs=25):
    """Appendix-A formula with explicit loops, for a single item."""
    v = 1.0 / (1.0 + np.exp(-logits))
    size = v.shape[0]
    coords = [(x, y, z) for x in range(size) for y in range(size) for z in range(size)]
    v_flat = np.array([v[c] for c in coords])
    mass = v_flat.sum()
    log_p = 0.0
    grad = np.zeros(len(coords))
    for k in range(n_dirs):
        s = (math.cos(2 * math.pi * k / n_dirs), math.sin(2 * math.pi * k / n_dirs))
        step = (int(round(s[0])), int(round(s[1])))
        proj = np.array([(x + 0.5) * s[0] + (y + 0.5) * s[1] for x, y, _ in coords])
        mu = (proj * v_flat).sum() / mass
        sigma = max(math.sqrt(((proj - mu) ** 2 * v_flat * (1 - v_flat)).sum()) / mass, sigma_floor)
        beyond = ndtr((proj - mu) / sigma)
        h = np.zeros(len(coords))
        for n, (x, y, z) in enumerate(coords):
            if other[x, y, z] >= 0.5:
                continue
            below = 1.0 if z == 0 else other[x, y, z - 1]
            bx, by = x + step[0], y + step[1]
            beside = other[bx, by, z] if 0 <= bx < size and 0 <= by < size else 0.0
            h[n] = 1 - (1 - below) * (1 - beside)
        u = np.prod(1 - v_flat * beyond * h)
        log_p += math.log(1 - u)
        h_hat = (h >= 0.5).astype(float)
        factors = 1 - beyond * (v_flat >= 0.5) * h_hat
        for n in range(len(coords)):
            others = np.prod(np.delete(factors, n))
            grad[n] += beyond[n] * h_hat[n] * others / (1 - u)
    return log_p, grad.reshape(v.shape)


def test_vectorized_matches_the_appendix_formula_on_a_small_grid():
    rng = np.random.default_rng(3)
    size = 5
    logits = rng.normal(0.0, 3.0, (size, size, size))
    other = (rng.random((size, size, size)) > 0.75).astype(float)
    ref_value, ref_grad = _naive_reference(logits, other)
    value, grad = stability_value_and_gradient(
        torch.tensor(logits, dtype=torch.float32)[None], torch.tensor(other, dtype=torch.float32)[None]
    )
    assert value.item() == pytest.approx(ref_value, rel=1e-4, abs=1e-5)
    np.testing.assert_allclose(grad[0].double().numpy(), ref_grad, rtol=1e-3, atol=1e-6)


def test_gradient_goes_through_sigmoid_mask_and_grad_output():
    rng = np.random.default_rng(5)
    size = 6
    logits = torch.tensor(rng.normal(0.0, 2.0, (2, size, size, size)), dtype=torch.float32)
    other = torch.tensor(rng.random((2, size, size, size)) > 0.8, dtype=torch.float32)
    unobserved = torch.tensor(rng.random((2, size, size, size)) > 0.5)
    _, grad_v = stability_value_and_gradient(logits, other)
    sigmoid = torch.sigmoid(logits)
    weights = torch.tensor([3.0, -0.5])
    leaf = logits.clone().requires_grad_(True)
    (stability_log_probability(leaf, other, unobserved) * weights).sum().backward()
    expected = grad_v * sigmoid * (1 - sigmoid) * unobserved * weights.view(-1, 1, 1, 1)
    torch.testing.assert_close(leaf.grad, expected)
    assert (leaf.grad[~unobserved] == 0).all()


def test_finite_for_extreme_logits_and_empty_grids():
    logits = torch.cat([torch.full((1, 8, 8, 8), -80.0), torch.full((1, 8, 8, 8), 80.0)])
    logits[1, :, :, 4:] = -80.0
    logits = logits.requires_grad_(True)
    other = torch.zeros(2, 8, 8, 8)
    value = stability_log_probability(logits, other, torch.ones(2, 8, 8, 8, dtype=torch.bool))
    (-value.sum()).backward()
    assert torch.isfinite(value).all() and torch.isfinite(logits.grad).all()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu():
    rng = np.random.default_rng(7)
    logits = torch.tensor(rng.normal(0.0, 3.0, (3, 16, 16, 16)), dtype=torch.float32)
    other = torch.tensor(rng.random((3, 16, 16, 16)) > 0.9, dtype=torch.float32)
    value_cpu, grad_cpu = stability_value_and_gradient(logits, other)
    value_gpu, grad_gpu = stability_value_and_gradient(logits.cuda(), other.cuda())
    torch.testing.assert_close(value_gpu.cpu(), value_cpu, rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(grad_gpu.cpu(), grad_cpu, rtol=1e-3, atol=1e-5)

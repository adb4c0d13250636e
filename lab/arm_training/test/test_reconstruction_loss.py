import torch
import torch.nn.functional as F

from arm_training.reconstruction.losses import reconstruction_loss, surface_shell


def _cube(d=10, lo=2, hi=8):
    occupancy = torch.zeros(1, d, d, d)
    occupancy[:, lo:hi, lo:hi, lo:hi] = 1
    return occupancy


def test_surface_shell_is_the_outer_layers_of_the_solid():
    occupancy = _cube()
    shell = surface_shell(occupancy, thickness_voxels=2)
    assert shell.sum() == 6**3 - 2**3
    assert shell[0, 4:6, 4:6, 4:6].sum() == 0 and shell[0, 2, 2, 2] == 1
    assert (shell <= occupancy).all()
    edge = torch.zeros(1, 4, 4, 4)
    edge[:, :2] = 1  # touching the grid border: outside counts as empty
    assert surface_shell(edge, 1).sum() == edge.sum()


def test_without_extras_it_is_the_voxel_cross_entropy():
    occupancy = _cube()
    logits = torch.randn(1, 10, 10, 10)
    expected = F.binary_cross_entropy_with_logits(logits, occupancy)
    torch.testing.assert_close(reconstruction_loss(logits, occupancy, surface_weight=0.0), expected)


def test_surface_term_and_positive_weight_penalise_missing_occupied_voxels():
    occupancy = _cube()
    empty_prediction = torch.full((1, 10, 10, 10), -4.0)
    base = reconstruction_loss(empty_prediction, occupancy, surface_weight=0.0)
    with_surface = reconstruction_loss(empty_prediction, occupancy, surface_weight=1.0)
    shell = surface_shell(occupancy)
    torch.testing.assert_close(with_surface - base, (shell * F.softplus(torch.tensor(4.0))).mean())
    assert reconstruction_loss(empty_prediction, occupancy, pos_weight=3.0, surface_weight=0.0) > base


def test_gradient_moves_logits_towards_the_target():
    occupancy = _cube()
    logits = torch.zeros(1, 10, 10, 10, requires_grad=True)
    reconstruction_loss(logits, occupancy, pos_weight=2.0).backward()
    assert (logits.grad[occupancy > 0] < 0).all() and (logits.grad[occupancy == 0] > 0).all()
    exact = torch.where(occupancy > 0, torch.tensor(30.0), torch.tensor(-30.0))
    assert reconstruction_loss(exact, occupancy) < 1e-6

"""Known answers for the inter-task mappings (tatl_mj.transfer.intertask_mapping, manifold_alignment)."""

import numpy as np
import pytest

from tatl_mj.transfer.intertask_mapping import AffineMapping, IdentityMapping, Mapping
from tatl_mj.transfer.manifold_alignment import align_manifolds


def _known_map() -> np.ndarray:
    """A = permutation @ scaling @ rotation (30, -50, 70 degrees about x, y, z)."""

    def rot(axis, deg):
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        i, j = [k for k in range(3) if k != axis]
        r = np.eye(3)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        return r

    rotation = rot(2, 70) @ rot(1, -50) @ rot(0, 30)
    return np.eye(3)[[2, 0, 1]] @ np.diag([2.0, 0.5, 1.0]) @ rotation


def _cloud(rng, n):
    """A curved, anisotropic 3-D cloud: its local geometry varies from point to point."""
    x = rng.normal(size=(n, 3)) * [1.0, 0.6, 0.3]
    x[:, 2] += x[:, 0] ** 2
    return x


def test_alignment_recovers_a_rotation_scaling_permutation_map():
    """Target = A x (shuffled, each set with its own noise 1e-3). With no correspondence given,
    chi maps each source point near its true partner: measured median error 0.26% of the
    target's RMS radius (required < 2%); chi_plus inverts chi exactly (dim = d)."""
    rng = np.random.default_rng(1)
    a_map = _known_map()
    x = _cloud(rng, 600)
    perm = rng.permutation(len(x))
    source = x + 1e-3 * rng.normal(size=x.shape)
    target = x[perm] @ a_map.T + 1e-3 * rng.normal(size=x.shape)
    mapping = align_manifolds(source, target, n_neighbors=6, mu=1.0)
    assert isinstance(mapping, Mapping)
    radius = np.sqrt(((target - target.mean(axis=0)) ** 2).sum(axis=1).mean())
    err = np.median(np.linalg.norm(mapping.chi(x) - x @ a_map.T, axis=1)) / radius
    print(f"alignment median relative error {err:.4f}")
    assert err < 0.02, err
    probe = rng.normal(size=(20, 3))
    np.testing.assert_allclose(mapping.chi_plus(mapping.chi(probe)), probe, atol=1e-8)
    # The shared coordinates of true partners agree.
    gap = np.linalg.norm(mapping.embed_source(x) - mapping.embed_target(x @ a_map.T), axis=1)
    assert np.median(gap) < 0.05 * np.linalg.norm(mapping.embed_source(x), axis=1).mean()


def test_identity_and_affine_mappings():
    s = np.random.default_rng(0).normal(size=(5, 2))
    np.testing.assert_array_equal(IdentityMapping().chi(s), s)
    np.testing.assert_array_equal(IdentityMapping().chi_plus(s), s)
    affine = AffineMapping([[0.0, 2.0], [-1.0, 0.0]], [1.0, 3.0])
    np.testing.assert_allclose(affine.chi(s), np.stack([2 * s[:, 1] + 1, -s[:, 0] + 3], axis=1))
    np.testing.assert_allclose(affine.chi_plus(affine.chi(s)), s, atol=1e-12)
    assert isinstance(affine, Mapping) and isinstance(IdentityMapping(), Mapping)


def test_degenerate_samples_raise_clear_errors():
    rng = np.random.default_rng(0)
    good = rng.normal(size=(100, 3))
    with pytest.raises(ValueError, match="rank-deficient"):
        align_manifolds(np.hstack([good[:, :2], np.ones((100, 1))]), good)
    with pytest.raises(ValueError, match="at least"):
        align_manifolds(good[:5], good)
    with pytest.raises(ValueError, match="NaN"):
        align_manifolds(np.where(good > 2, np.nan, good), good)
    with pytest.raises(ValueError, match="dim"):
        align_manifolds(good, good[:, :2], dim=3)
    with pytest.raises(ValueError, match="n_neighbors"):
        align_manifolds(good, good, n_neighbors=1)


def test_different_dimensions_give_the_right_shapes():
    rng = np.random.default_rng(2)
    source = _cloud(rng, 200)[:, :2]
    target = _cloud(rng, 200)
    mapping = align_manifolds(source, target)
    assert mapping.alpha.shape == (2, 2) and mapping.beta.shape == (3, 2)
    assert mapping.chi(source[:7]).shape == (7, 3)
    assert mapping.chi_plus(target[:7]).shape == (7, 2)

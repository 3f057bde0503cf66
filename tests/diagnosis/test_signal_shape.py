"""The shape network's input and its numpy evaluation (issue 46): what the fit trains on is
what a diagnosis reads, and the numpy forward pass reads as PyTorch's does."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from plantcheck.diagnosis.cause_model import (
    blended,
    decide,
    load_cause_model,
    shipped_cause_model,
)
from plantcheck.diagnosis.evidence import FEATURE_NAMES
from plantcheck.diagnosis.signal_shape import (
    SCALARS,
    SHAPE_CLIP,
    SHAPE_SAMPLES,
    ShapeInput,
    ShapeNet,
    shape_input,
    shape_log_probabilities,
)
from plantcheck.simulator.corpus import CLASSES


def _random_net(seed: int = 0) -> ShapeNet:
    rng = np.random.default_rng(seed)
    chans, kernels = (3, 4, 5, 6, 7), (9, 7, 5, 5)
    conv_w = tuple(rng.normal(0, 0.3, (chans[i + 1], chans[i], k)) for i, k in enumerate(kernels))
    conv_b = tuple(rng.normal(0, 0.1, c) for c in chans[1:])
    dense_w = (rng.normal(0, 0.3, (8, 2 * chans[-1] + len(SCALARS))), rng.normal(0, 0.3, (6, 8)))
    dense_b = (rng.normal(0, 0.1, 8), rng.normal(0, 0.1, 6))
    n = len(SCALARS)
    return ShapeNet(conv_w, conv_b, dense_w, dense_b, np.zeros(n), np.ones(n), np.full(n, -3.0),
                    np.full(n, 3.0))  # fmt: skip


def test_a_window_of_any_length_becomes_three_bounded_channels() -> None:
    rng = np.random.default_rng(2)
    for n in (150, 3_600, 20_000):
        pv = 50.0 + np.cumsum(rng.normal(0, 0.1, n))
        op = 40.0 + rng.normal(0, 1.0, n)
        sp = np.full(n, 50.0)
        sp[n // 2 :] = 52.0
        x = shape_input(pv, op, sp, "level")
        assert x.channels.shape == (3, SHAPE_SAMPLES) and x.scalars.shape == (len(SCALARS),)
        assert np.all(np.abs(x.channels) <= SHAPE_CLIP) and np.all(np.isfinite(x.scalars))
        # kept as float16 in the fit's cache: read the same numbers here
        np.testing.assert_array_equal(x.channels, x.channels.astype(np.float16))
        assert x.scalars[SCALARS.index("integrating")] == 1.0
        assert x.scalars[SCALARS.index("log_samples")] == pytest.approx(np.log10(n), rel=1e-6)


def test_the_blend_is_a_softmax_of_weighted_log_probabilities() -> None:
    model = shipped_cause_model()
    assert model is not None
    net = _random_net()
    rng = np.random.default_rng(3)
    x = ShapeInput(rng.normal(size=(3, SHAPE_SAMPLES)), rng.normal(size=len(SCALARS)))
    log_shape = shape_log_probabilities(net, x)
    assert abs(float(np.exp(log_shape).sum()) - 1.0) < 1e-12
    both = replace(model, shape=net, shape_more=(), shape_weight=0.3, blend_temperature=0.9)
    ev = rng.normal(size=len(FEATURE_NAMES))
    trees = decide(model, ev)
    d = decide(both, ev, x)
    want = blended(np.log(trees.probabilities), log_shape, 0.3, 0.9)
    np.testing.assert_allclose(d.probabilities, want, rtol=1e-12)
    assert d.shape_probabilities is not None
    np.testing.assert_allclose(d.raw, trees.raw)  # the trees' own reading is kept
    # without the window's shape the trees decide alone
    np.testing.assert_array_equal(decide(both, ev).probabilities, trees.probabilities)


def test_networks_averaged_read_as_their_normalised_geometric_mean() -> None:
    """Several networks' log-probabilities are averaged and normalised again before the
    blend, so the shape's probabilities still add up to 1."""
    model = shipped_cause_model()
    assert model is not None
    nets = [_random_net(k) for k in (7, 8, 9)]
    rng = np.random.default_rng(4)
    x = ShapeInput(rng.normal(size=(3, SHAPE_SAMPLES)), rng.normal(size=len(SCALARS)))
    logs = np.array([shape_log_probabilities(net, x) for net in nets])
    mean = logs.mean(axis=0)
    want_shape = mean - np.log(np.exp(mean).sum())
    three = replace(model, shape=nets[0], shape_more=tuple(nets[1:]), shape_weight=0.4,
                    blend_temperature=1.2)  # fmt: skip
    ev = rng.normal(size=len(FEATURE_NAMES))
    d = decide(three, ev, x)
    assert d.shape_probabilities is not None
    np.testing.assert_allclose(np.log(d.shape_probabilities), want_shape, rtol=1e-12)
    want = blended(np.log(decide(model, ev).probabilities), want_shape, 0.4, 1.2)
    np.testing.assert_allclose(d.probabilities, want, rtol=1e-12)


def test_a_model_file_keeps_its_shape_network(tmp_path: Path) -> None:
    from plantcheck.service.cause_model_fit import save_model

    model = shipped_cause_model()
    assert model is not None
    net = _random_net(4)
    path = tmp_path / "m.npz"
    base = tuple(np.log(np.full(len(CLASSES), 1.0 / len(CLASSES))).tolist())
    save_model(replace(model, shape=net, shape_more=(), shape_weight=0.25,
                       blend_temperature=1.1, shape_base=base), path)  # fmt: skip
    back = load_cause_model(path)
    assert back.shape is not None and back.shape_weight == 0.25 and back.blend_temperature == 1.1
    assert back.shape_base == base
    for a, b in zip(back.shape.conv_w + back.shape.dense_w, net.conv_w + net.dense_w, strict=True):
        np.testing.assert_array_equal(a, b)
    assert back.classes == CLASSES and back.shape_more == ()
    # further networks are kept, in their order
    more = (_random_net(5), _random_net(6))
    save_model(replace(back, shape_more=more), path)
    again = load_cause_model(path)
    assert len(again.shape_more) == 2
    for got, net_k in zip(again.shape_more, more, strict=True):
        np.testing.assert_array_equal(got.dense_w[1], net_k.dense_w[1])


def test_a_model_file_without_an_array_it_needs_names_it(tmp_path: Path) -> None:
    from plantcheck.service.cause_model_fit import save_model

    model = shipped_cause_model()
    assert model is not None
    path = tmp_path / "m.npz"
    save_model(model, path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files if k != "shape_scalar_min"}
    np.savez_compressed(path, **arrays)
    with pytest.raises(ValueError, match=r"shape_scalar_min.*plantcheck model fit"):
        load_cause_model(path)


def test_the_numpy_network_reads_as_pytorch_does() -> None:
    """The fit exports the trained module with its batch normalisation folded in; numpy must
    then give PyTorch's probabilities."""
    torch = pytest.importorskip("torch", reason="PyTorch (the fit extra) is not installed")
    from plantcheck.service.shape_model_fit import export_shape_net, shape_module

    torch.manual_seed(5)
    mu, sd = torch.randn(len(SCALARS)), torch.rand(len(SCALARS)) + 0.5
    net = shape_module(torch.nn, mu, sd)
    # a few training steps move the batch statistics off their start
    opt = torch.optim.SGD(net.parameters(), 0.01)
    for _ in range(3):
        x = torch.randn(16, 3, SHAPE_SAMPLES)
        loss = net(x, torch.randn(16, len(SCALARS))).square().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    net.eval()
    exported = export_shape_net(net, mu, sd, torch.full_like(mu, -9.0), torch.full_like(mu, 9.0))
    x = torch.randn(4, 3, SHAPE_SAMPLES)
    sc = torch.randn(4, len(SCALARS))
    with torch.no_grad():
        want = torch.log_softmax(net(x, sc), 1).double().numpy()
    for i in range(4):
        got = shape_log_probabilities(
            exported, ShapeInput(x[i].double().numpy(), sc[i].double().numpy())
        )
        np.testing.assert_allclose(got, want[i], atol=1e-5)


def test_the_network_fit_is_repeatable() -> None:
    """Seeded, on fixed threads, deterministic: the same windows give the same weights, so
    ``plantcheck model fit`` rebuilds the shipped file byte for byte."""
    pytest.importorskip("torch", reason="PyTorch (the fit extra) is not installed")
    from plantcheck.service.shape_model_fit import CorpusShapes, fit_shape_net

    rng = np.random.default_rng(6)
    n = 300
    shapes = CorpusShapes(
        rng.normal(size=(n, 3, SHAPE_SAMPLES)).astype(np.float16),
        rng.normal(size=(n, len(SCALARS))).astype(np.float32),
        rng.integers(0, len(CLASSES), n),
        np.ones(n, dtype=bool),
    )
    a, b = fit_shape_net(shapes), fit_shape_net(shapes)
    for x, y in zip(a.conv_w + a.dense_w + a.conv_b, b.conv_w + b.dense_w + b.conv_b, strict=True):
        np.testing.assert_array_equal(x, y)
    c = fit_shape_net(shapes, seed=1)
    assert not np.array_equal(a.dense_w[1], c.dense_w[1])
    # the command's ensemble: the k-th network is the one drawn from seed + k
    from plantcheck.service.cause_model_fit import with_networks

    model = shipped_cause_model()
    assert model is not None
    two = with_networks(model, shapes, 2, seed=0)
    assert two.shape is not None and len(two.shape_more) == 1
    for net, want in ((two.shape, a), (two.shape_more[0], c)):
        np.testing.assert_array_equal(net.dense_w[1], want.dense_w[1])
    with pytest.raises(ValueError, match="networks"):
        with_networks(model, shapes, 0)


def test_a_scalar_outside_the_fits_range_reads_as_its_nearest_end() -> None:
    net = _random_net(7)
    rng = np.random.default_rng(8)
    chans = rng.normal(size=(3, SHAPE_SAMPLES))
    inside = np.zeros(len(SCALARS))
    inside[SCALARS.index("integrating")] = 3.0
    beyond = inside.copy()
    beyond[SCALARS.index("integrating")] = 1e6
    np.testing.assert_array_equal(
        shape_log_probabilities(net, ShapeInput(chans, beyond)),
        shape_log_probabilities(net, ShapeInput(chans, inside)),
    )


def test_a_window_without_a_shape_leaves_the_network_finite() -> None:
    """A window the checks stop on after leaving a frozen transmitter out has no shape (NaN
    throughout); the network is fitted on every window, judged or not, and one such window
    turned every weight into NaN from the first epoch (fifty-fourth session's refit)."""
    pytest.importorskip("torch", reason="PyTorch (the fit extra) is not installed")
    from plantcheck.service.shape_model_fit import CorpusShapes, fit_shape_net

    rng = np.random.default_rng(7)
    n = 200
    channels = rng.normal(size=(n, 3, SHAPE_SAMPLES)).astype(np.float16)
    channels[5] = np.nan
    judged = np.ones(n, dtype=bool)
    judged[5] = False
    shapes = CorpusShapes(
        channels,
        rng.normal(size=(n, len(SCALARS))).astype(np.float32),
        rng.integers(0, len(CLASSES), n),
        judged,
    )
    net = fit_shape_net(shapes)
    for w in net.conv_w + net.dense_w + net.conv_b:
        assert np.isfinite(w).all()

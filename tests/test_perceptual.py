"""FovVideoVDP (JOD) on tiny image pairs; skipped without the perceptual extra."""
import numpy as np
import pytest

from foveated_mi import perceptual
from foveated_mi.validate import ParameterError


def _pair(noise, seed=0):
    rng = np.random.default_rng(seed)
    ref = (0.25 + 0.5 * rng.random((18, 32, 3))).astype(np.float32)
    return ref, np.clip(ref + rng.normal(0.0, noise, ref.shape), 0, 1).astype(np.float32)


def test_jod_orders_noise_levels_and_feels_the_gaze():
    pytest.importorskip("pyfvvdp")
    pytest.importorskip("torch")
    ref, _ = _pair(0.0)
    assert perceptual.jod(ref, ref) == pytest.approx(10.0, abs=1e-3)
    j = [perceptual.jod(ref, _pair(n)[1]) for n in (0.02, 0.1)]
    assert 10.0 > j[0] > j[1]
    # the same noise, only in the left half: fixating on it scores lower than looking away
    test = ref.copy()
    test[:, :16] = _pair(0.1)[1][:, :16]
    near = perceptual.jod(ref, test, gaze=(0.1, 0.5), ppd=8.0)
    far = perceptual.jod(ref, test, gaze=(0.95, 0.5), ppd=8.0)
    assert near < far
    with pytest.raises(ParameterError, match="display = 'nope'"):
        perceptual.jod(ref, ref, display="nope")


def test_without_the_extra_jod_names_the_install_command(monkeypatch):
    monkeypatch.setattr(perceptual, "available", lambda: False)
    ref, test = _pair(0.1)
    with pytest.raises(ParameterError, match=r"pip install -e '\.\[perceptual\]'"):
        perceptual.jod(ref, test)

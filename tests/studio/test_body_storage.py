"""Compact model-file storage (studio.body.storage)."""

import numpy as np

from studio.body import BodyModel
from studio.body.storage import BLOCK, dequantize_blocks, quantize_blocks, save_model_file


def test_block_quantisation_error_is_half_a_step():
    rng = np.random.default_rng(0)
    a = rng.normal(0, 1, (3, 5 * BLOCK + 17)).astype(np.float32)  # a ragged last block
    a[1, :BLOCK] = 0.0  # an all-zero block
    q, scale = quantize_blocks(a)
    assert q.dtype == np.int8 and q.shape == a.shape and scale.shape == (3, 6)
    back = dequantize_blocks(q, scale)
    step = np.repeat(scale.astype(np.float32), BLOCK, axis=1)[:, : a.shape[1]]
    assert np.all(np.abs(back - a) <= 0.5 * step * 1.01 + 1e-7)
    assert np.all(back[1, :BLOCK] == 0.0)


def test_saved_file_loads_and_is_reproducible(tmp_path):
    rng = np.random.default_rng(1)
    arrays = {"female/D_basis": rng.normal(0, 1, (2, 300)).astype(np.float16),
              "Q_coef": rng.normal(0, 1, (4, 7, 9)).astype(np.float32), "n": np.array(5)}
    save_model_file(tmp_path / "a.npz", arrays)
    save_model_file(tmp_path / "b.npz", arrays)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    with np.load(tmp_path / "a.npz") as z:
        assert set(z.files) == {"female/D_basis_q", "female/D_basis_scale", "Q_coef", "n"}
        assert z["n"].shape == () and int(z["n"]) == 5 and z["Q_coef"].dtype == np.float16
        back = dequantize_blocks(z["female/D_basis_q"], z["female/D_basis_scale"])
    assert np.abs(back - arrays["female/D_basis"].astype(np.float32)).max() < 0.02


def test_shipped_model_is_stored_compactly():
    from studio.body.model import DATA_FILE

    with np.load(DATA_FILE) as z:
        assert z["female/D_basis_q"].dtype == np.int8
    assert DATA_FILE.stat().st_size < 11e6  # 10.3 MB: both pose deformations (the search body's)
    model = BodyModel.load("female")
    assert model.D_basis.shape == (30, 9 * len(model.faces))

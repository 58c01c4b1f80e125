"""Model files saved by the flat ``sysid/`` layout still load and predict the same after the move to sub-packages.

The files in ``tests/data/models_before_subpackages`` were written at ``ad03a55`` (README there); a model file names
its identifier by registry id, never by module path, so the move must not change what they predict.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from sysid import load_model, read_record
from sysid.registry import IDENTIFIERS

HERE = Path(__file__).parent / "data" / "models_before_subpackages"
EXPECTED = json.loads((HERE / "expected.json").read_text())["models"]


def test_every_identifier_has_an_old_file():
    assert sorted(EXPECTED) == sorted(IDENTIFIERS)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_old_file_predicts_as_it_did(name):
    if name in ("narx-mlp", "narx-mlp-sim", "rnn", "ss-encoder", "wh-net"):
        pytest.importorskip("torch")
    model = load_model(HERE / EXPECTED[name]["file"])
    assert model.name == name
    val = read_record(HERE / "val.npz")
    for horizon, key in ((None, "free_run"), (1, "one_step")):
        got = np.asarray(model.predict(val, horizon=horizon)).ravel()
        want = np.asarray(EXPECTED[name][key])
        scale = float(np.max(np.abs(want))) or 1.0
        # 1e-6 of the output's range: the torch and BLAS kernel sets a CPU picks move the last digits only
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * scale, err_msg=f"{name} {key}")

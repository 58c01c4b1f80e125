"""FMUs in a C host: ``tests/c/fmu_host.c`` loads the FMU binary with ``dlopen`` as a simulation tool
does (fmi2Instantiate, 3000 × fmi2DoStep, fmi2Terminate, fmi2FreeInstance, dlclose), linked with libpython as
pythonfmu 0.7 requires, and must exit 0 every time; its outputs equal the model's own free run.

Before the fix in :func:`twins.fmu.slave._finalize_at_exit` every FMU of the project ended such a process with
SIGSEGV (139) or a glibc abort (134)."""

import os
import shutil
import site
import subprocess
import sys
import sysconfig
import zipfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

HOST_C = Path(__file__).parent / "c" / "fmu_host.c"
LIBDIR = sysconfig.get_config_var("LIBDIR") or ""
LDLIB = sysconfig.get_config_var("LDLIBRARY") or ""

pytestmark = pytest.mark.skipif(
    sys.platform != "linux" or shutil.which("gcc") is None or not LDLIB.endswith(".so")
    or not (Path(LIBDIR) / LDLIB).exists(),
    reason="needs Linux, gcc and a shared libpython")


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    exe = tmp_path_factory.mktemp("host") / "fmu_host"
    lib = LDLIB[3:].rsplit(".so", 1)[0]  # libpython3.11.so -> python3.11
    subprocess.run(["gcc", "-O1", "-o", str(exe), str(HOST_C), "-Wl,--no-as-needed", "-ldl", "-lm", f"-L{LIBDIR}",
                    f"-l{lib}", f"-Wl,-rpath,{LIBDIR}"], check=True, capture_output=True)
    return exe


def _unpack(fmu: Path, folder: Path):
    with zipfile.ZipFile(fmu) as z:
        z.extractall(folder)
    root = ET.parse(folder / "modelDescription.xml").getroot()
    vr = {v.get("name"): v.get("valueReference") for v in root.iter("ScalarVariable")}
    binary = next((folder / "binaries" / "linux64").glob("*.so"))
    return binary, root.get("guid"), vr["u"], vr["y"]


def _env():
    env = dict(os.environ, MALLOC_CHECK_="3")
    # the interpreter the wrapper starts must find this environment's packages (numpy, numba, torch ...)
    paths = [p for p in site.getsitepackages() if Path(p).exists()] + [str(Path(__file__).resolve().parents[1])]
    env["PYTHONPATH"] = os.pathsep.join(paths)
    return env


def _run(host, fmu, folder, fs, n=3000, out=None):
    binary, guid, vu, vy = _unpack(fmu, folder)
    args = [str(host), str(binary), (folder / "resources").resolve().as_uri(), guid, vu, vy, repr(fs), str(n)]
    if out is not None:
        args.append(str(out))
    return subprocess.run(args, env=_env(), capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def model_fmu(tmp_path_factory):
    from sysid.polynomial import NARXPoly
    from tests._polysys import narx_record
    from twins.fmu.model_export import export_model_fmu

    d = tmp_path_factory.mktemp("fmu")
    m = NARXPoly().fit(narx_record(1500, seed=0, noise=0.01).replace(fs=1000.0))
    return m, export_model_fmu(m, d / "narx.fmu")


def test_c_host_runs_model_fmu_and_exits_cleanly(host, model_fmu, tmp_path):
    m, fmu = model_fmu
    for i in range(3):
        out = tmp_path / f"y{i}.txt"
        res = _run(host, fmu, tmp_path / f"x{i}", 1000.0, out=out)
        assert res.returncode == 0, (res.returncode, res.stderr[-2000:])
        u = np.sin(2 * np.pi * 0.01 * np.arange(3000))  # the host's input
        np.testing.assert_allclose(np.loadtxt(out), m.predict(u), rtol=1e-12, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("twin", ["acoustic", "cantilever"])
def test_c_host_twin_fmu_20_of_20(host, twin, tmp_path):
    from twins.fmu import export_fmu
    from twins.registry import get_twin

    fmu = export_fmu(get_twin(twin)(), tmp_path / f"{twin}.fmu")
    fs = {"acoustic": 100e6, "cantilever": 1e4}[twin]
    codes = [_run(host, fmu, tmp_path / f"x{i}", fs).returncode for i in range(20)]
    assert codes == [0] * 20

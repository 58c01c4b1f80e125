"""FMUs in a C host: ``tests/c/fmu_host.c`` loads the FMU binary with ``dlopen`` as a simulation tool
does (fmi2Instantiate, 3000 × fmi2DoStep, fmi2Terminate, fmi2FreeInstance, dlclose) and must exit 0 every
time; its outputs equal the model's own free run. Two builds of the host: linked with libpython (what
pythonfmu 0.7's wrapper alone requires) and a plain C program, which only works through the loader the export
puts in front of the wrapper (:mod:`twins.fmu.shim`).

Before the fix in :func:`twins.fmu.slave._finalize_at_exit` every FMU of the project ended such a process with
SIGSEGV (139) or a glibc abort (134)."""

import os
import shutil
import site
import subprocess
import sys
import sysconfig
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

HOST_C = Path(__file__).parent / "c" / "fmu_host.c"
LIBDIR = sysconfig.get_config_var("LIBDIR") or ""
LDLIB = sysconfig.get_config_var("LDLIBRARY") or ""

pytestmark = pytest.mark.skipif(
    sys.platform != "linux"
    or shutil.which("gcc") is None
    or not LDLIB.endswith(".so")
    or not (Path(LIBDIR) / LDLIB).exists(),
    reason="needs Linux, gcc and a shared libpython",
)


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    exe = tmp_path_factory.mktemp("host") / "fmu_host"
    lib = LDLIB[3:].rsplit(".so", 1)[0]  # libpython3.11.so -> python3.11
    subprocess.run(
        [
            "gcc",
            "-O1",
            "-o",
            str(exe),
            str(HOST_C),
            "-Wl,--no-as-needed",
            "-ldl",
            "-lm",
            f"-L{LIBDIR}",
            f"-l{lib}",
            f"-Wl,-rpath,{LIBDIR}",
        ],
        check=True,
        capture_output=True,
    )
    return exe


@pytest.fixture(scope="module")
def plain_host(tmp_path_factory):
    """The same host, not linked with libpython."""
    exe = tmp_path_factory.mktemp("plain") / "fmu_host"
    subprocess.run(["gcc", "-O1", "-o", str(exe), str(HOST_C), "-ldl", "-lm"], check=True, capture_output=True)
    needed = subprocess.run(["ldd", str(exe)], capture_output=True, text=True).stdout
    assert "libpython" not in needed
    return exe


def _unpack(fmu: Path, folder: Path):
    if not (folder / "modelDescription.xml").exists():
        with zipfile.ZipFile(fmu) as z:
            z.extractall(folder)
    root = ET.parse(folder / "modelDescription.xml").getroot()
    vr = {v.get("name"): v.get("valueReference") for v in root.iter("ScalarVariable")}
    binary = folder / "binaries" / "linux64" / f"{root.find('CoSimulation').get('modelIdentifier')}.so"
    return binary, root.get("guid"), vr["u"], vr["y"]


def _env():
    env = dict(os.environ, MALLOC_CHECK_="3")
    # the interpreter the wrapper starts must find this environment's packages (numpy, numba, torch ...)
    paths = [p for p in site.getsitepackages() if Path(p).exists()] + [str(Path(__file__).resolve().parents[1])]
    env["PYTHONPATH"] = os.pathsep.join(paths)
    return env


def _run(host, fmu, folder, fs, n=3000, out=None):
    """One host process on the FMU extracted to ``folder`` (extracted there by the first run: later runs find
    the numba cache the first one wrote into ``resources/``, as a tool that extracts an FMU once does)."""
    binary, guid, vu, vy = _unpack(fmu, folder)
    args = [str(host), str(binary), (folder / "resources").resolve().as_uri(), guid, vu, vy, repr(fs), str(n)]
    if out is not None:
        args.append(str(out))
    return subprocess.run(args, env=_env(), capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def model_fmu(tmp_path_factory):
    from sysid.polynomial.narmax import NARXPoly
    from tests._polysys import narx_record
    from twins.fmu.model_export import export_model_fmu

    d = tmp_path_factory.mktemp("fmu")
    m = NARXPoly().fit(narx_record(1500, seed=0, noise=0.01).replace(fs=1000.0))
    return m, export_model_fmu(m, d / "narx.fmu")


def test_c_host_runs_model_fmu_and_exits_cleanly(host, model_fmu, tmp_path):
    m, fmu = model_fmu
    for i in range(3):
        out = tmp_path / f"y{i}.txt"
        res = _run(host, fmu, tmp_path / "x", 1000.0, out=out)
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


def test_plain_c_host_needs_the_loader(plain_host, model_fmu, tmp_path):
    """pythonfmu's wrapper alone does not load into a plain C program; the FMU's binary (the loader) does."""
    m, fmu = model_fmu
    out = tmp_path / "y.txt"
    res = _run(plain_host, fmu, tmp_path / "x", 1000.0, out=out)
    assert res.returncode == 0, (res.returncode, res.stderr[-2000:])
    u = np.sin(2 * np.pi * 0.01 * np.arange(3000))
    np.testing.assert_allclose(np.loadtxt(out), m.predict(u), rtol=1e-12, atol=1e-12)
    binary, guid, vu, vy = _unpack(fmu, tmp_path / "x")
    wrapped = binary.with_name(binary.stem + ".pythonfmu.so")
    res = subprocess.run(
        [
            str(plain_host),
            str(wrapped),
            (tmp_path / "x" / "resources").resolve().as_uri(),
            guid,
            vu,
            vy,
            "1000.0",
            "10",
        ],
        env=_env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 4 and "undefined symbol" in res.stderr, (res.returncode, res.stderr)


def _twin_fmu(twin, folder):
    from twins.fmu import export_fmu
    from twins.registry import get_twin

    return export_fmu(get_twin(twin)(), folder / f"{twin}.fmu"), {"acoustic": 100e6, "cantilever": 1e4}[twin]


@pytest.mark.heavy
@pytest.mark.parametrize("twin", ["acoustic", "cantilever"])
def test_plain_c_host_twin_fmu_3_runs(plain_host, twin, tmp_path):
    """The fast variant of the 20-run check below: 3 runs of 300 steps, same outputs each time; the
    cantilever's equal its native ``simulate`` (the FMU's output at the end of step k is sample k)."""
    fmu, fs = _twin_fmu(twin, tmp_path)
    outs = []
    for i in range(3):
        outs.append(tmp_path / f"y{i}.txt")
        res = _run(plain_host, fmu, tmp_path / "x", fs, n=300, out=outs[-1])
        assert res.returncode == 0, (res.returncode, res.stderr[-2000:])
    ys = [np.loadtxt(o) for o in outs]
    assert all(np.array_equal(ys[0], y) for y in ys[1:])
    if twin == "cantilever":
        from twins.registry import get_twin

        u = np.sin(2 * np.pi * 0.01 * np.arange(300))
        np.testing.assert_array_equal(ys[0], get_twin(twin)().simulate(u, fs))


@pytest.mark.slow
@pytest.mark.parametrize("twin", ["acoustic", "cantilever"])
def test_plain_c_host_twin_fmu_20_of_20(plain_host, twin, tmp_path):
    fmu, fs = _twin_fmu(twin, tmp_path)
    codes = [_run(plain_host, fmu, tmp_path / "x", fs).returncode for i in range(20)]
    assert codes == [0] * 20

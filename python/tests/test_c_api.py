"""The C API (include/moreau/moreau.h) through ctypes, as any FFI would call it: the library
named by MOREAU_C_LIBRARY (set by the build's test environment), no Python module involved."""
import ctypes
import os

import numpy as np
import pytest

import moreau

# Directional and adjoint products agree with the full matrix to this relative accuracy (the
# same implicit-function-theorem solves, associated differently).
PRODUCT_TOLERANCE = 1e-10

OK, INVALID_ARGUMENT, SIMULATION_FAILED, BUFFER_TOO_SMALL, NOT_AVAILABLE = range(5)


@pytest.fixture(scope="module")
def lib():
    path = os.environ.get("MOREAU_C_LIBRARY")
    if not path:
        pytest.fail("MOREAU_C_LIBRARY is not set (the build's test environment sets it)")
    lib = ctypes.CDLL(path)
    size_p = ctypes.POINTER(ctypes.c_size_t)
    double_p = ctypes.POINTER(ctypes.c_double)
    handle_p = ctypes.POINTER(ctypes.c_void_p)
    signatures = {
        "moreau_last_error": ([], ctypes.c_char_p),
        "moreau_version": ([], ctypes.c_char_p),
        "moreau_scene_builtin": ([ctypes.c_char_p, handle_p], ctypes.c_int),
        "moreau_scene_parse": ([ctypes.c_char_p, ctypes.c_char_p, handle_p], ctypes.c_int),
        "moreau_scene_free": ([ctypes.c_void_p], None),
        "moreau_scene_sizes": ([ctypes.c_void_p, size_p, size_p, size_p, size_p], ctypes.c_int),
        "moreau_run_create": ([ctypes.c_void_p, ctypes.c_char_p, handle_p], ctypes.c_int),
        "moreau_run_free": ([ctypes.c_void_p], None),
        "moreau_run_set_real": ([ctypes.c_void_p, ctypes.c_char_p, ctypes.c_double],
                                ctypes.c_int),
        "moreau_run_set_bool": ([ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int], ctypes.c_int),
        "moreau_run_set_reals": ([ctypes.c_void_p, ctypes.c_char_p, double_p, ctypes.c_size_t],
                                 ctypes.c_int),
        "moreau_run_set_initial_state": ([ctypes.c_void_p, double_p, ctypes.c_size_t],
                                         ctypes.c_int),
        "moreau_run_simulate": ([ctypes.c_void_p], ctypes.c_int),
        "moreau_run_final_state": ([ctypes.c_void_p, double_p, ctypes.c_size_t, size_p],
                                   ctypes.c_int),
    }
    for name in ("moreau_run_sensitivities", "moreau_run_directional", "moreau_run_adjoint"):
        signatures[name] = ([ctypes.c_void_p, double_p, ctypes.c_size_t, size_p, size_p],
                            ctypes.c_int)
    for name, (arguments, result) in signatures.items():
        function = getattr(lib, name)
        function.argtypes = arguments
        function.restype = result
    return lib


def _doubles(array):
    array = np.ascontiguousarray(array, dtype=float)
    return array, array.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def _matrix(lib, function, run):
    """A column-major result matrix: size query first, then the values."""
    rows, cols = ctypes.c_size_t(), ctypes.c_size_t()
    assert function(run, None, 0, ctypes.byref(rows), ctypes.byref(cols)) == OK
    out = np.zeros(rows.value * cols.value)
    _, pointer = _doubles(out)
    assert function(run, pointer, out.size, ctypes.byref(rows), ctypes.byref(cols)) == OK
    return out.reshape(cols.value, rows.value).T


@pytest.mark.parametrize("integrator", ["fesd", "timestepping"])
def test_directional_and_adjoint_equal_products_with_the_full_matrix(lib, integrator):
    scene = ctypes.c_void_p()
    assert lib.moreau_scene_builtin(b"F1", ctypes.byref(scene)) == OK
    n = [ctypes.c_size_t() for _ in range(4)]
    assert lib.moreau_scene_sizes(scene, *[ctypes.byref(v) for v in n]) == OK
    nx, n_theta = n[0].value, n[0].value + n[1].value + n[2].value * n[3].value
    run = ctypes.c_void_p()
    assert lib.moreau_run_create(scene, integrator.encode(), ctypes.byref(run)) == OK
    lib.moreau_scene_free(scene)
    rng = np.random.default_rng(7)
    v = rng.standard_normal((n_theta, 3))
    w = rng.standard_normal((nx, 2))
    v_flat, v_pointer = _doubles(v.flatten(order="F"))
    w_flat, w_pointer = _doubles(w.flatten(order="F"))
    assert lib.moreau_run_set_real(run, b"h", 0.05) == OK
    assert lib.moreau_run_set_bool(run, b"sensitivities", 1) == OK
    assert lib.moreau_run_set_reals(run, b"directions", v_pointer, v_flat.size) == OK
    assert lib.moreau_run_set_reals(run, b"adjoint_weights", w_pointer, w_flat.size) == OK
    x0, x0_pointer = _doubles([0.4, 0.05])
    assert lib.moreau_run_set_initial_state(run, x0_pointer, 2) == OK
    assert lib.moreau_run_simulate(run) == OK, lib.moreau_last_error()
    full = _matrix(lib, lib.moreau_run_sensitivities, run)
    directional = _matrix(lib, lib.moreau_run_directional, run)
    adjoint = _matrix(lib, lib.moreau_run_adjoint, run)
    scale = np.abs(full).max()
    assert full.shape == (nx, n_theta)
    assert np.abs(directional - full @ v).max() <= PRODUCT_TOLERANCE * scale
    assert np.abs(adjoint - w.T @ full).max() <= PRODUCT_TOLERANCE * scale
    # The same run through the Python package gives the same full matrix.
    result = moreau.simulate(moreau.scene("F1").set(**{"x0.x1": 0.4, "x0.x2": 0.05}),
                             integrator, h=0.05, sensitivities=True)
    python_full = np.hstack([result.sensitivities.dx_dx0, result.sensitivities.dx_dp])
    assert np.abs(python_full - full).max() <= PRODUCT_TOLERANCE * scale
    lib.moreau_run_free(run)


def test_bad_input_gives_a_status_and_a_message(lib):
    scene = ctypes.c_void_p()
    assert lib.moreau_scene_builtin(b"no_such_scene", ctypes.byref(scene)) == INVALID_ARGUMENT
    assert b"no_such_scene" in lib.moreau_last_error()
    assert lib.moreau_scene_parse(b"x0 = [", b"bad.toml", ctypes.byref(scene)) == INVALID_ARGUMENT
    assert b"bad.toml" in lib.moreau_last_error()
    assert lib.moreau_run_simulate(None) == INVALID_ARGUMENT
    assert lib.moreau_scene_builtin(b"F1", ctypes.byref(scene)) == OK
    run = ctypes.c_void_p()
    assert lib.moreau_run_create(scene, b"fesd", ctypes.byref(run)) == OK
    x = np.zeros(2)
    _, x_pointer = _doubles(x)
    count = ctypes.c_size_t()
    assert lib.moreau_run_final_state(run, x_pointer, 2, ctypes.byref(count)) == NOT_AVAILABLE
    assert lib.moreau_run_set_real(run, b"h", float("nan")) == OK  # checked at simulate
    assert lib.moreau_run_simulate(run) == INVALID_ARGUMENT
    assert b"h" in lib.moreau_last_error()
    assert lib.moreau_run_set_real(run, b"h", 0.05) == OK
    assert lib.moreau_run_simulate(run) == OK
    assert lib.moreau_run_final_state(run, x_pointer, 1, ctypes.byref(count)) == BUFFER_TOO_SMALL
    assert count.value == 2
    assert lib.moreau_run_directional(run, None, 0, None, None) == NOT_AVAILABLE
    lib.moreau_run_free(run)
    lib.moreau_scene_free(scene)
    assert lib.moreau_version().decode().count(".") == 2


def test_the_documented_example_compiles_and_runs(tmp_path):
    """The C program of docs/c-api.md, compiled with the system's C compiler against the
    library and run: the documentation's example stays correct."""
    import re
    import shutil
    import subprocess

    docs = os.environ.get("MOREAU_DOCS")
    include = os.environ.get("MOREAU_INCLUDE")
    library = os.environ.get("MOREAU_C_LIBRARY")
    if not (docs and include and library):
        pytest.fail("MOREAU_DOCS, MOREAU_INCLUDE and MOREAU_C_LIBRARY are set by the build")
    compiler = shutil.which("cc") or shutil.which("gcc")
    assert compiler, "a C compiler (cc) is needed"
    with open(os.path.join(docs, "c-api.md"), encoding="utf-8") as f:
        blocks = re.findall(r"```c\n(.*?)```", f.read(), flags=re.S)
    assert len(blocks) == 1, "docs/c-api.md has one C program"
    source = tmp_path / "app.c"
    source.write_text(blocks[0])
    program = tmp_path / "app"
    flags = os.environ.get("MOREAU_C_FLAGS", "").split()
    library_dir = os.path.dirname(library)
    subprocess.run([compiler, "-std=c11", "-Wall", "-Werror", *flags, str(source), "-I", include,
                    library, f"-Wl,-rpath,{library_dir}", "-o", str(program)], check=True,
                   capture_output=True, text=True)
    completed = subprocess.run([str(program)], capture_output=True, text=True, timeout=120)
    assert completed.returncode == 0, completed.stderr
    assert "dx1(T)/dtheta" in completed.stdout

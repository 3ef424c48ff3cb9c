"""numba's cache folder follows every source a kernel is compiled from (common/jitcache.py)."""
import os
import subprocess
import sys

from common import jitcache

CALLEE = "from numba import njit\n\n\n@njit(cache=True)\ndef f():\n    return {}\n"
CALLER = "from numba import njit\n\nfrom .callee import f\n\n\n@njit(cache=True)\ndef g():\n    return f()\n"


def _write_package(root, value):
    pkg = root / "kern"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "callee.py").write_text(CALLEE.format(value))
    (pkg / "caller.py").write_text(CALLER)


def _run_caller(root, cache_dir):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(root))
    code = "from kern.caller import g; print(g())"
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=root, capture_output=True, text=True,
                         timeout=120, check=True)
    return int(out.stdout.split()[-1])


def test_a_kernel_calling_another_files_kernel_runs_the_callees_current_code(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    _write_package(src, 1)
    fixed = tmp_path / "one-folder"                      # numba's own keying: one folder for all versions
    d1 = jitcache.sources_digest(src, ("kern",))
    assert _run_caller(src, fixed) == 1
    assert _run_caller(src, tmp_path / d1) == 1
    _write_package(src, 2)                               # only the callee's file changes (same size)
    d2 = jitcache.sources_digest(src, ("kern",))
    assert d2 != d1
    assert _run_caller(src, fixed) == 1                  # the caller's cache still holds the old callee
    assert _run_caller(src, tmp_path / d2) == 2          # one folder per version of the sources: current


def test_the_digest_covers_paths_and_contents_of_every_source(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "x.py").write_text("X = 1\n")
    d0 = jitcache.sources_digest(tmp_path, ("a",))
    (tmp_path / "a" / "x.py").write_text("X = 2\n")
    d1 = jitcache.sources_digest(tmp_path, ("a",))
    (tmp_path / "a" / "x.py").rename(tmp_path / "a" / "y.py")
    d2 = jitcache.sources_digest(tmp_path, ("a",))
    (tmp_path / "a" / "notes.txt").write_text("not a source")
    assert len({d0, d1, d2}) == 3 and jitcache.sources_digest(tmp_path, ("a",)) == d2


def test_this_process_caches_its_kernels_under_this_versions_folder():
    import numba.core.config as config
    path = jitcache.configure()
    assert path.endswith(jitcache.sources_digest()) and os.environ["NUMBA_CACHE_DIR"] == path
    assert config.CACHE_DIR == path


def test_a_fresh_process_configures_the_cache_without_importing_numba_or_numpy(tmp_path):
    """``import common`` in a process that did not inherit NUMBA_CACHE_DIR leaves numba and
    numpy unimported (a real-time child sets numpy's threads before numpy loads: the jitter
    loop, common/rt.py single_threaded_numerics); numba, imported afterwards, reads the
    folder from the variable."""
    import subprocess
    import sys
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["ELLIPSLED_NUMBA_CACHE"] = str(tmp_path)
    code = ("import sys, os, common\n"
            "print('numba' in sys.modules, 'numpy' in sys.modules)\n"
            "import numba.core.config as c\n"
            "print(c.CACHE_DIR == os.environ['NUMBA_CACHE_DIR'], c.CACHE_DIR.startswith(sys.argv[1]))\n")
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, timeout=120,
                       env=env, cwd=str(jitcache.ROOT))
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "False", "True", "True"], r.stdout

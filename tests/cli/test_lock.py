"""The locked install (requirements.lock, `make lock`): every dependency of pyproject.toml, extras included,
at one exact version that its specifier admits, each with its sha256 hashes; torch is the 2.13.0 CPU
build and nothing pulls CUDA packages."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[2]


def parse_lock(text: str) -> dict[str, tuple[Version, list[str]]]:
    """Canonical name -> (pinned version, sha256 hashes) of a hashed requirements file (uv/pip-compile format)."""
    pins: dict[str, tuple[Version, list[str]]] = {}
    current = None
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip().rstrip("\\").strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith("--hash=sha256:"):
            if current is None:
                raise ValueError(f"requirements.lock line {lineno}: hash without a requirement")
            pins[current][1].append(line.removeprefix("--hash=sha256:"))
            continue
        if line.startswith("--"):  # --find-links and other options of the file
            continue
        m = re.fullmatch(r"([A-Za-z0-9_.\-]+)==(\S+)", line)
        if m is None:
            raise ValueError(f"requirements.lock line {lineno}: not 'name==version': {line!r}")
        current = canonicalize_name(m.group(1))
        pins[current] = (Version(m.group(2)), [])
    return pins


@pytest.fixture(scope="module")
def lock():
    return parse_lock((ROOT / "requirements.lock").read_text())


def test_parse_lock_reads_pins_and_hashes_and_refuses_unpinned_lines():
    text = "--find-links /x\n\nFoo_Bar==1.2 \\\n    --hash=sha256:aa \\\n    --hash=sha256:bb\n    # via x\n"
    assert parse_lock(text) == {"foo-bar": (Version("1.2"), ["aa", "bb"])}
    with pytest.raises(ValueError, match="line 1"):
        parse_lock("foo>=1.2\n")


def test_every_pin_has_hashes(lock):
    assert len(lock) > 50
    assert [name for name, (_, hashes) in lock.items() if not hashes] == []
    assert all(re.fullmatch(r"[0-9a-f]{64}", h) for _, hashes in lock.values() for h in hashes)


def test_torch_is_the_pinned_cpu_build_and_no_cuda_package_is_locked(lock):
    assert lock["torch"][0] == Version("2.13.0+cpu")
    assert [n for n in lock if n.startswith(("nvidia-", "triton", "cuda-"))] == []


def test_every_pyproject_dependency_is_locked_at_a_version_it_admits(lock):
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    specs = list(project["dependencies"])
    for extra in project["optional-dependencies"].values():
        specs += extra
    bad = []
    for spec in specs:
        req = Requirement(spec)
        pin = lock.get(canonicalize_name(req.name))
        if pin is None or not req.specifier.contains(pin[0]):
            bad.append(f"{spec} (locked: {pin[0] if pin else 'missing'})")
    assert bad == [], "requirements.lock is stale, run `make lock`: " + ", ".join(bad)

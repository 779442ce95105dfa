"""Builds the plenoxd_client package (pyproject.toml has the rest): its version and its gRPC
stubs.

Version: the daemon's, from `project(plenoxd VERSION x.y.z)` in the repository's
CMakeLists.txt, the one place it is written. plenoxd reports that version in
ServerInfo.version, and the client compares the two on connect.

Stubs: generated here, while the package is built, from proto/plenoxd/v1/plenoxd.proto and
grpc-proto's grpc/health/v1/health.proto, with protoc and grpc_python_plugin: the tools the C++
build compiles the same files with (CMake passes its own as PLX_PROTOC and
PLX_GRPC_PYTHON_PLUGIN; otherwise they are looked up on PATH). `pip install ./clients/python`
and the wheel the CMake build makes are therefore built the same way, and neither can drift
from the .proto. They go into plenoxd_client/_generated/ of the built package, never into the
source folder.

Environment: PLX_SOURCE_DIR (the repository; default: two folders up), PLX_PROTOC,
PLX_GRPC_PYTHON_PLUGIN, PLX_GRPC_PROTO_ROOT (default /usr/share/grpc-proto).
"""

import atexit
import os
import re
import shutil
import subprocess
import tempfile

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE_DIR = os.path.abspath(os.environ.get("PLX_SOURCE_DIR")
                             or os.path.join(HERE, os.pardir, os.pardir))
GRPC_PROTO_ROOT = os.environ.get("PLX_GRPC_PROTO_ROOT") or "/usr/share/grpc-proto"

# (include folder, .proto relative to it): plenoxd's API, and the standard health service
# (the daemon serves grpc.health.v1; Client.health() calls it).
PROTOS = (
    (os.path.join(SOURCE_DIR, "proto"), "plenoxd/v1/plenoxd.proto"),
    (GRPC_PROTO_ROOT, "grpc/health/v1/health.proto"),
)


def fail(message):
    raise SystemExit(f"plenoxd_client build: {message}")


def project_version():
    """x.y.z of `project(plenoxd VERSION x.y.z ...)` in the top-level CMakeLists.txt."""
    path = os.path.join(SOURCE_DIR, "CMakeLists.txt")
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except OSError as e:
        fail(f"cannot read the version from {path} ({e}); build from a plenoxd checkout or "
             "set PLX_SOURCE_DIR to one")
    match = re.search(r"^\s*project\(\s*plenoxd\s+VERSION\s+([0-9]+(?:\.[0-9]+)*)\b", text,
                      re.MULTILINE)
    if match is None:
        fail(f"{path} has no `project(plenoxd VERSION x.y.z ...)` line")
    return match.group(1)


def tool(variable, name, debian_package):
    """The program ${variable} names, else `name` on PATH."""
    path = shutil.which(os.environ.get(variable) or name)
    if not path:
        fail(f"needs {name} to generate the gRPC stubs: install Debian's {debian_package} "
             f"or set {variable} to it (now: {os.environ.get(variable) or 'unset'})")
    return path


def relative_import(text, dotted_package, module, path):
    """The generated *_pb2_grpc.py imports its messages by the .proto's package path (e.g.
    `from plenoxd.v1 import plenoxd_pb2`); inside plenoxd_client._generated they are a sibling
    module. Exactly one such line is expected: anything else means protoc's output changed, and
    the build stops rather than ship a module that cannot import."""
    pattern = re.compile(rf"^from {re.escape(dotted_package)} import {module} as ", re.MULTILINE)
    rewritten, count = pattern.subn(f"from . import {module} as ", text)
    if count != 1:
        fail(f"{path}: expected one `from {dotted_package} import {module}` line, found {count}")
    return rewritten


def generate_stubs(out_dir, version):
    """Writes the *_pb2.py, *_pb2.pyi and *_pb2_grpc.py modules of PROTOS, and __init__.py
    with API_VERSION, into out_dir."""
    protoc = tool("PLX_PROTOC", "protoc", "protobuf-compiler")
    plugin = tool("PLX_GRPC_PYTHON_PLUGIN", "grpc_python_plugin", "protobuf-compiler-grpc")
    os.makedirs(out_dir, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="plenoxd_client_protoc_") as scratch:
        for include, proto in PROTOS:
            if not os.path.isfile(os.path.join(include, proto)):
                hint = ("install Debian's grpc-proto or set PLX_GRPC_PROTO_ROOT"
                        if include == GRPC_PROTO_ROOT else "set PLX_SOURCE_DIR to a checkout")
                fail(f"{os.path.join(include, proto)} is missing: {hint}")
            command = [protoc, f"--proto_path={include}", f"--python_out={scratch}",
                       f"--pyi_out={scratch}", f"--grpc_out={scratch}",
                       f"--plugin=protoc-gen-grpc={plugin}", os.path.join(include, proto)]
            result = subprocess.run(command, capture_output=True, text=True)
            if result.returncode != 0:
                fail(f"{' '.join(command)} failed:\n{result.stderr}")
            folder, name = os.path.split(proto)
            stem = os.path.splitext(name)[0] + "_pb2"
            for suffix in (".py", ".pyi", "_grpc.py"):
                source = os.path.join(scratch, folder, stem + suffix)
                with open(source, encoding="utf-8") as f:
                    text = f.read()
                if suffix == "_grpc.py":
                    text = relative_import(text, folder.replace("/", "."), stem, source)
                with open(os.path.join(out_dir, stem + suffix), "w", encoding="utf-8") as f:
                    f.write(text)
    with open(os.path.join(out_dir, "__init__.py"), "w", encoding="utf-8") as f:
        f.write('"""Written when plenoxd_client was built (clients/python/setup.py): the gRPC '
                'stubs of\nplenoxd/v1/plenoxd.proto and grpc/health/v1/health.proto, and the '
                'API version."""\n\n'
                "# plenoxd's version (CMakeLists.txt), which the daemon reports in "
                "ServerInfo.version.\n"
                f'API_VERSION = "{version}"\n')


class BuildPyWithStubs(build_py):
    """build_py, plus the generated plenoxd_client/_generated/ package."""

    def run(self):
        super().run()
        if self.dry_run:
            return
        # An editable install imports the package from the source folder, so the stubs go
        # there (ignored by git); every other build writes them into the built package only.
        package_dir = (os.path.join(HERE, "plenoxd_client")
                       if getattr(self, "editable_mode", False)
                       else os.path.join(self.build_lib, "plenoxd_client"))
        generate_stubs(os.path.join(package_dir, "_generated"), VERSION)


# setuptools writes build/ and *.egg-info into the current folder, which pip makes the source
# folder: a scratch folder keeps the checkout clean, and leaves no stale build/lib behind whose
# old files a later wheel would pick up.
SCRATCH = tempfile.mkdtemp(prefix="plenoxd_client_build_")
atexit.register(shutil.rmtree, SCRATCH, ignore_errors=True)
VERSION = project_version()

setup(
    version=VERSION,
    cmdclass={"build_py": BuildPyWithStubs},
    options={"build": {"build_base": os.path.join(SCRATCH, "build")},
             "egg_info": {"egg_base": SCRATCH}},
)

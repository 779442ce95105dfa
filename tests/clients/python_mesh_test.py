#!/usr/bin/env python3
"""The installed plenoxd_client fetching meshes as binary glTF from a real plenoxd: the full
mesh, a level of detail, and the mesh of a box of the map (a headset fetching its room).

    <venv>/bin/python tests/clients/python_mesh_test.py --plenoxd <plenoxd> --plenox <plenox> \\
      [--installed-in <venv>]

Maps a small `plenox synth` sequence in-process (`plenox map`) into a temporary data directory,
starts plenoxd on it, and reads every GLB the client writes back with the standard library
alone (struct, json): the header, the JSON chunk's accessors and the asset's extras, so the
checks do not rest on the client's own reader. Exits 0 when everything passed, 1 with a list of
failures, 77 (skip) when this interpreter has no grpc.
"""

import argparse
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import traceback

try:
    import grpc  # noqa: F401
except ImportError as missing:
    print(f"SKIP: {sys.executable} cannot import grpc ({missing}); install Debian's "
          "python3-grpcio")
    sys.exit(77)

import plenoxd_client
from plenoxd_client import Client, PlenoxdError

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from python_client_test import Daemon, Failures  # noqa: E402  (the same daemon helper)

FRAMES, WIDTH, HEIGHT = 30, 96, 72
VOXEL_SIZE = 0.04


def read_glb(path):
    """(header length field, file size, the JSON chunk as a dict) of the GLB at `path`."""
    with open(path, "rb") as f:
        data = f.read()
    magic, version, length = struct.unpack_from("<3I", data, 0)
    if magic != 0x46546C67 or version != 2:
        raise ValueError(f"{path}: not a glTF 2 binary file")
    chunk_length, chunk_type = struct.unpack_from("<2I", data, 12)
    if chunk_type != 0x4E4F534A:
        raise ValueError(f"{path}: the first chunk is not JSON")
    return length, len(data), json.loads(data[20:20 + chunk_length])


def primitive_counts(gltf):
    """(vertices, triangles, POSITION min, POSITION max) of the file's one primitive, or zeros
    and None for a file without a mesh (an empty region)."""
    if not gltf.get("meshes"):
        return 0, 0, None, None
    primitive = gltf["meshes"][0]["primitives"][0]
    position = gltf["accessors"][primitive["attributes"]["POSITION"]]
    indices = gltf["accessors"][primitive["indices"]]
    return position["count"], indices["count"] // 3, position["min"], position["max"]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--plenoxd", required=True)
    parser.add_argument("--plenox", required=True)
    parser.add_argument("--keep", action="store_true", help="keep the work folder")
    parser.add_argument("--installed-in", help="the venv plenoxd_client must be imported from")
    args = parser.parse_args()
    where = os.path.realpath(plenoxd_client.__file__)
    if args.installed_in and not where.startswith(os.path.realpath(args.installed_in) + os.sep):
        print(f"FAIL: plenoxd_client was imported from {where}, not from the package installed "
              f"in {args.installed_in}")
        return 1

    failures = Failures()
    work = tempfile.mkdtemp(prefix="plenoxd_py_mesh_")
    daemon = None
    began = time.monotonic()
    try:
        sequence = os.path.join(work, "sequence")
        data_dir = os.path.join(work, "mesh_data")
        os.makedirs(data_dir)
        for argv in (["synth", "--out", sequence, "--frames", str(FRAMES), "--width",
                      str(WIDTH), "--height", str(HEIGHT)],
                     ["map", "--dataset", sequence, "--out", os.path.join(data_dir, "room.plx"),
                      "--every", "10", "--voxel-size", str(VOXEL_SIZE), "--quiet"]):
            r = subprocess.run([args.plenox, *argv], capture_output=True, text=True, timeout=300)
            if not failures.check(r.returncode == 0, f"plenox {argv[0]}"):
                print(r.stdout, r.stderr)
                return 1
        daemon = Daemon(args.plenoxd, work, "mesh")  # loads <data-dir>/room.plx
        with Client(daemon.target, timeout=120.0) as client:
            full_path = os.path.join(work, "room.glb")
            full = client.export_mesh("room", full_path, format="glb")
            length, size, gltf = read_glb(full_path)
            vertices, triangles, lo, hi = primitive_counts(gltf)
            failures.check(length == size == full.bytes and triangles == full.faces > 1000
                           and vertices == full.vertices and full.full_faces == full.faces,
                           f"the full mesh as GLB: header length {length} = file size {size}, "
                           f"{triangles} triangles, {vertices} vertices as the client reports")
            failures.check(gltf["asset"]["extras"]["plenoxd"]["triangles"] == triangles
                           and "region" not in gltf["asset"]["extras"]["plenoxd"],
                           "its extras count the triangles and name no region")

            budget = full.faces // 10
            lod_path = os.path.join(work, "room_lod.glb")
            lod = client.export_mesh("room", lod_path, format="glb", lod_triangles=budget)
            _, _, lod_gltf = read_glb(lod_path)
            _, lod_triangles, _, _ = primitive_counts(lod_gltf)
            extras = lod_gltf["asset"]["extras"]["plenoxd"]
            failures.check(0 < lod_triangles <= budget and lod.faces == lod_triangles
                           and extras["full_triangles"] == full.faces == lod.full_faces
                           and extras["lod_error_m"] > 0,
                           f"a level of detail of {budget}: {lod_triangles} triangles, the full "
                           f"mesh's {extras['full_triangles']} and an error of "
                           f"{1000 * extras['lod_error_m']:.1f} mm in the extras")

            # Two boxes that share a face at the middle of the mesh's longest extent: each
            # holds the triangles of the voxels whose centres are in it, so they split the
            # full mesh between them, and neither reaches more than half a voxel past its box.
            axis = max(range(3), key=lambda a: hi[a] - lo[a])
            middle = 0.5 * (lo[axis] + hi[axis])
            halves = []
            for side in ("lower", "upper"):
                box = [v - 1.0 for v in lo] + [v + 1.0 for v in hi]
                box[axis + (3 if side == "lower" else 0)] = middle
                path = os.path.join(work, f"room_{side}.glb")
                half = client.export_mesh("room", path, format="glb", bbox=box)
                _, _, half_gltf = read_glb(path)
                _, half_triangles, half_lo, half_hi = primitive_counts(half_gltf)
                region = half_gltf["asset"]["extras"]["plenoxd"].get("region")
                slack = VOXEL_SIZE / 2 + 1e-4
                inside = half_triangles > 0 and all(
                    half_lo[a] >= box[a] - slack and half_hi[a] <= box[a + 3] + slack
                    for a in range(3))
                failures.check(inside and half.faces == half_triangles
                               and region == {"min": box[:3], "max": box[3:]},
                               f"the {side} half: {half_triangles} triangles within half a "
                               f"voxel of its box, the box in the extras")
                halves.append(half_triangles)
            share = halves[0] / max(1, full.faces)
            failures.check(sum(halves) == full.faces and 0.2 < share < 0.8,
                           f"the halves split the full mesh: {halves[0]} + {halves[1]} = "
                           f"{full.faces} triangles ({100 * share:.0f} % below the middle)")

            # plenox map keeps the keyframes in the file, so the default is the surface they
            # saw; the density's has the backs of walls besides, so more triangles.
            density_path = os.path.join(work, "room_density.glb")
            density = client.export_mesh("room", density_path, format="glb", surface="density")
            observed = client.export_mesh("room", density_path, format="glb", surface="observed")
            failures.check(observed.faces == full.faces and density.faces > full.faces,
                           f"surface: the default is the observed one ({observed.faces} = "
                           f"{full.faces} triangles), the density's has more ({density.faces})")
            try:
                client.export_mesh("room", density_path, surface="seen")
                failures.check(False, "an unknown surface raises ValueError")
            except ValueError as e:
                failures.check("surface" in str(e), "an unknown surface raises ValueError")

            empty_path = os.path.join(work, "nowhere.glb")
            empty = client.export_mesh("room", empty_path, format="glb",
                                       bbox=(50, 50, 50, 51, 51, 51))
            _, _, empty_gltf = read_glb(empty_path)
            failures.check(empty.faces == 0 and not empty_gltf.get("meshes")
                           and empty_gltf["asset"]["extras"]["plenoxd"]["region"]["min"]
                           == [50, 50, 50],
                           "a box with nothing mapped in it: a valid GLB without a mesh")
            failures.expect_error(
                lambda: client.export_mesh("room", empty_path, format="glb",
                                           bbox=(0, 0, 0, 1, -1, 1)),
                "INVALID_ARGUMENT", "a box with min > max on y", "region")
            try:
                client.export_mesh("room", empty_path, bbox=(0, 0, 1))
                failures.check(False, "a bbox of three numbers raises ValueError")
            except ValueError as e:
                failures.check("bbox" in str(e), "a bbox of three numbers raises ValueError "
                               "before any call")
            except PlenoxdError as e:
                failures.check(False, f"a bbox of three numbers raises ValueError (got {e})")
        code = daemon.stop()
        failures.check(code == 0, f"daemon: SIGTERM -> exit code 0 (got {code})")
    except Exception:  # noqa: BLE001
        failures.check(False, f"raised\n{traceback.format_exc()}")
    finally:
        if daemon is not None and daemon.proc.poll() is None:
            daemon.proc.kill()
            daemon.proc.wait()
        if failures.items and daemon is not None:
            print(f"--- daemon log (tail) ---\n{daemon.log_tail()}")
        if args.keep or failures.items:
            print(f"work folder kept: {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)

    print(f"\n{time.monotonic() - began:.1f} s in all")
    if failures.items:
        print(f"{len(failures.items)} check(s) FAILED:")
        for item in failures.items:
            print(f"  - {item.splitlines()[0]}")
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())

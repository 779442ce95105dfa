#!/usr/bin/python3
"""Mesh benchmark: `plenox export --mesh` against Open3D's ScalableTSDFVolume mesh.

For one TUM-layout sequence (default ../shared/data/replica_room0):

    plenox map --dataset DIR --out TMP/map.plx --every K --voxel-size V [--time-budget S] --json
    plenox export --map TMP/map.plx --out TMP/mesh.ply --mesh --json
    Open3D ScalableTSDFVolume(voxel_length=V, sdf_trunc=4 V) of the same keyframes (ground-truth
    poses), extract_triangle_mesh()

and, with --lod-fraction F (default 0.1; 0 = off), also the same map's level of detail at F
of the full mesh's triangles (`plenox export --mesh --lod-triangles N`, written as PLY for
Open3D to read; the GLB of it is written too and its size reported), and scores every mesh
against the ground truth: the measured depth of the held-out frames
(i % K == K // 2) back-projected with their ground-truth poses. Each mesh is sampled uniformly
(fixed seed); samples are kept where a held-out view sees them (inside its image, in front of or
within 5 cm behind its measured depth), as the NICE-SLAM-style evaluations cull, so both
systems are judged on what the held-out views show.

    accuracy      mean distance from mesh samples to the ground-truth points
    completeness  mean distance from ground-truth points to mesh samples
    chamfer       (accuracy + completeness) / 2
    precision / recall / F-score at 2 cm: fractions of samples / points within 2 cm

Prints a markdown table with the machine and commit; run it with /usr/bin/python3
(Debian's python3-open3d, python3-opencv).

    /usr/bin/python3 bench/mesh_bench.py --every 4 --voxel-size 0.02

The goal of issue 23 (part 3): the 10 % level of detail's F-score within 0.05 of the full
mesh's; the notes under the table give the difference.
"""

import argparse
import datetime
import os
import sys
import tempfile
import time

os.environ.setdefault("OMP_WAIT_POLICY", "passive")  # see bench/peers/open3d_tsdf.py

import numpy as np  # noqa: E402

try:
    import open3d as o3d  # noqa: E402
except ImportError as exc:  # pragma: no cover - depends on the interpreter
    sys.exit("mesh_bench.py: %s. Run it with /usr/bin/python3 (python3-open3d)." % exc)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_common import (REPO, CommandError, GroundTruth, git_commit, load_rgbd,  # noqa: E402
                          log, machine_line, read_frames, read_intrinsics, render_table,
                          run_json, set_log_prefix, write_report)

TOLERANCE = 0.02      # m, the F-score distance
BEHIND = 0.05         # m, how far behind a held-out view's depth a sample still counts as seen
SAMPLES = 400_000     # points sampled on each mesh
PIXEL_STEP = 2        # ground truth: every 2nd pixel of the held-out frames
MAX_DEPTH = 10.0


def frame_data(dataset, every, max_frames=0):
    intr = read_intrinsics(dataset)
    frames = read_frames(dataset)
    if max_frames:
        frames = frames[:max_frames]
    gt = GroundTruth(os.path.join(dataset, "groundtruth.txt"))
    keys = [i for i in range(len(frames)) if i % every == 0]
    held = [i for i in range(len(frames)) if i % every == every // 2]
    return intr, frames, gt, keys, held


def backproject(depth_m, pose, intr, step):
    h, w = depth_m.shape
    v, u = np.mgrid[0:h:step, 0:w:step]
    z = depth_m[::step, ::step]
    ok = (z > 0) & (z <= MAX_DEPTH)
    x = (u[ok] + 0.5 - intr["cx"]) / intr["fx"] * z[ok]
    y = (v[ok] + 0.5 - intr["cy"]) / intr["fy"] * z[ok]
    pc = np.stack([x, y, z[ok]], axis=1)
    return pc @ pose[:3, :3].T + pose[:3, 3]


def seen_by_any(points, views, intr):
    """Mask of points that some held-out view sees (in its image, not hidden > BEHIND behind
    its measured depth)."""
    seen = np.zeros(len(points), dtype=bool)
    for depth_m, pose in views:
        R, t = pose[:3, :3], pose[:3, 3]
        pc = (points - t) @ R
        z = pc[:, 2]
        front = z > 0.05
        u = np.full(len(points), -1, dtype=np.int64)
        v = np.full(len(points), -1, dtype=np.int64)
        u[front] = np.floor(intr["fx"] * pc[front, 0] / z[front] + intr["cx"]).astype(np.int64)
        v[front] = np.floor(intr["fy"] * pc[front, 1] / z[front] + intr["cy"]).astype(np.int64)
        inside = front & (u >= 0) & (v >= 0) & (u < intr["width"]) & (v < intr["height"])
        measured = np.zeros(len(points))
        measured[inside] = depth_m[v[inside], u[inside]]
        seen |= inside & (measured > 0) & (z <= measured + BEHIND)
    return seen


def score(mesh, truth, views, intr):
    if len(mesh.triangles) == 0:
        return None
    o3d.utility.random.seed(7)
    samples = np.asarray(mesh.sample_points_uniformly(SAMPLES).points)
    visible = samples[seen_by_any(samples, views, intr)]
    every = np.asarray(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(samples))
                       .compute_point_cloud_distance(
                           o3d.geometry.PointCloud(o3d.utility.Vector3dVector(truth))))
    s = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(visible))
    g = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(truth))
    acc = np.asarray(s.compute_point_cloud_distance(g))
    comp = np.asarray(g.compute_point_cloud_distance(s))
    precision = float((acc < TOLERANCE).mean())
    recall = float((comp < TOLERANCE).mean())
    f = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return {"accuracy_cm": 100 * acc.mean(), "completeness_cm": 100 * comp.mean(),
            "chamfer_cm": 50 * (acc.mean() + comp.mean()), "precision": precision,
            "recall": recall, "fscore": f, "triangles": len(mesh.triangles),
            "seen_fraction": len(visible) / len(samples),
            "precision_all": float((every < TOLERANCE).mean())}


def open3d_mesh(frames, keys, gt, intr, voxel):
    volume = o3d.pipelines.integration.ScalableTSDFVolume(
        voxel_length=voxel, sdf_trunc=4 * voxel,
        color_type=o3d.pipelines.integration.TSDFVolumeColorType.RGB8)
    K = o3d.camera.PinholeCameraIntrinsic(intr["width"], intr["height"], intr["fx"], intr["fy"],
                                          intr["cx"], intr["cy"])
    for i in keys:
        depth, rgb = load_rgbd(frames[i], intr)
        pose = gt.pose(frames[i][0])
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.geometry.Image(rgb), o3d.geometry.Image(depth), depth_scale=intr["depth_scale"],
            depth_trunc=MAX_DEPTH, convert_rgb_to_intensity=False)
        volume.integrate(rgbd, K, np.linalg.inv(pose))
    return volume.extract_triangle_mesh()


def score_lod(args, name, map_path, work, exported, truth, views, intr):
    """The level of detail at args.lod_fraction of the full mesh's triangles: exported as PLY
    (scored) and as GLB (sized), and the full mesh's GLB for comparison."""
    budget = max(1, int(round(args.lod_fraction * exported["faces"])))
    base = [args.plenox, "export", "--map", map_path, "--mesh", "--iso-level",
            repr(args.iso_level), "--mesh-surface", args.surfaces.split(",")[0], "--json"]
    paths = {k: os.path.join(work, k) for k in ("lod.ply", "lod.glb", "full.glb")}
    began = time.monotonic()
    lod = run_json("%s plenox export LOD" % name,
                   base + ["--out", paths["lod.ply"], "--lod-triangles", str(budget)],
                   args.timeout)
    seconds = time.monotonic() - began
    lod_glb = run_json("%s plenox export LOD glb" % name,
                       base + ["--out", paths["lod.glb"], "--lod-triangles", str(budget)],
                       args.timeout)
    full_glb = run_json("%s plenox export glb" % name, base + ["--out", paths["full.glb"]],
                        args.timeout)
    if lod["faces"] > budget or lod_glb["faces"] != lod["faces"]:
        sys.exit("the level of detail has %d (PLY) / %d (GLB) triangles for a budget of %d"
                 % (lod["faces"], lod_glb["faces"], budget))
    mesh = o3d.io.read_triangle_mesh(paths["lod.ply"])
    if len(mesh.triangles) != lod["faces"]:
        sys.exit("Open3D read %d triangles, plenox wrote %d" % (len(mesh.triangles), lod["faces"]))
    s = score(mesh, truth, views, intr)
    s["seconds"] = seconds
    s["lod_error_m"] = lod["lod_error_m"]
    s["glb_bytes"] = lod_glb["bytes"]
    s["full_glb_bytes"] = full_glb["bytes"]
    s["notes"] = "--lod-triangles %d: extract + simplify, error %.1f mm" % (
        budget, 1000 * lod["lod_error_m"])
    return s


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", default=os.path.join(REPO, "..", "shared", "data",
                                                     "replica_room0"))
    p.add_argument("--plenox", default=os.path.join(REPO, "build", "clients", "plenox",
                                                    "plenox"))
    p.add_argument("--every", type=int, default=4)
    p.add_argument("--voxel-size", type=float, default=0.02)
    p.add_argument("--time-budget", type=float, default=None,
                   help="plenox map --time-budget (seconds)")
    p.add_argument("--iso-level", type=float, default=0.0, help="0 = plenox's default")
    p.add_argument("--lod-fraction", type=float, default=0.1,
                   help="also score the level of detail at this fraction of the triangles "
                        "(0 = off)")
    p.add_argument("--surfaces", default="observed,density",
                   help="plenox's mesh surfaces to score (--mesh-surface), comma-separated; "
                        "the first is the one the level of detail uses")
    p.add_argument("--map", help="score the meshes of this map file (made by plenox map with "
                                 "the same --every) instead of mapping again")
    p.add_argument("--no-peer", action="store_true", help="skip the Open3D TSDF mesh")
    p.add_argument("--timeout", type=float, default=1800)
    p.add_argument("--out", help="also write the report here")
    args = p.parse_args()
    set_log_prefix("mesh_bench")
    name = os.path.basename(os.path.normpath(args.dataset))
    intr, frames, gt, keys, held = frame_data(args.dataset, args.every)
    if args.voxel_size <= 0 or args.every < 2:
        sys.exit("--voxel-size must be > 0 and --every >= 2")

    views, truth = [], []
    for i in held:
        depth, _ = load_rgbd(frames[i], intr)
        pose = gt.pose(frames[i][0])
        depth_m = depth.astype(np.float64) / intr["depth_scale"]
        views.append((depth_m, pose))
        truth.append(backproject(depth_m, pose, intr, PIXEL_STEP))
    truth = np.concatenate(truth)
    log("%s: %d keyframes, %d held-out frames, %d ground-truth points"
        % (name, len(keys), len(held), len(truth)))

    rows = []
    with tempfile.TemporaryDirectory(prefix="plx_mesh_bench_") as work:
        map_path = os.path.join(work, "map.plx")
        mesh_path = os.path.join(work, "mesh.ply")
        cmd = [args.plenox, "map", "--dataset", args.dataset, "--out", map_path, "--every",
               str(args.every), "--voxel-size", repr(args.voxel_size), "--json", "--quiet"]
        if args.time_budget is not None:
            cmd += ["--time-budget", repr(args.time_budget)]
        try:
            if args.map:
                map_path, mapped = args.map, {}
            else:
                mapped = run_json("%s plenox map" % name, cmd, args.timeout)
        except CommandError as exc:
            sys.exit(str(exc))
        surfaces = [x for x in args.surfaces.split(",") if x]
        exported = None
        for surface in surfaces:
            began = time.monotonic()
            try:
                result = run_json("%s plenox export (%s)" % (name, surface),
                                  [args.plenox, "export", "--map", map_path, "--out", mesh_path,
                                   "--mesh", "--mesh-surface", surface, "--iso-level",
                                   repr(args.iso_level), "--json"], args.timeout)
            except CommandError as exc:
                sys.exit(str(exc))
            export_s = time.monotonic() - began
            exported = exported or result
            ours = o3d.io.read_triangle_mesh(mesh_path)
            if len(ours.triangles) != result["faces"]:
                sys.exit("Open3D read %d triangles, plenox wrote %d"
                         % (len(ours.triangles), result["faces"]))
            s = score(ours, truth, views, intr)
            s["seconds"] = export_s
            s["notes"] = ("map %.0f s, %d iterations" % (mapped["seconds"], mapped["iterations"])
                          if mapped else "map %s" % os.path.basename(map_path))
            rows.append(("plenox (ours), %s surface" % surface, s))
            log("ours (%s): %s" % (surface, s))
        if args.lod_fraction > 0 and exported is not None:
            rows.append(("plenox LOD %g %%" % (100 * args.lod_fraction),
                         score_lod(args, name, map_path, work, exported, truth, views, intr)))
            log("lod: %s" % rows[-1][1])

    if not args.no_peer:
        began = time.monotonic()
        peer = open3d_mesh(frames, keys, gt, intr, args.voxel_size)
        s = score(peer, truth, views, intr)
        s["seconds"] = time.monotonic() - began
        s["notes"] = "integrate + extract"
        rows.append(("Open3D ScalableTSDFVolume", s))
        log("open3d: %s" % s)

    cols = ["system", "triangles", "accuracy (cm)", "completeness (cm)", "Chamfer (cm)",
            "precision @2 cm", "recall @2 cm", "F-score @2 cm", "precision, unculled",
            "mesh seconds", "notes"]
    body = [[system, "%d" % r["triangles"], "%.2f" % r["accuracy_cm"],
             "%.2f" % r["completeness_cm"], "%.2f" % r["chamfer_cm"], "%.3f" % r["precision"],
             "%.3f" % r["recall"], "%.3f" % r["fscore"], "%.3f" % r["precision_all"],
             "%.1f" % r["seconds"], r["notes"]]
            for system, r in rows]
    header = ["Mesh accuracy on %s: keyframes every %d (%d), %d held-out frames, voxel %.3f m"
              % (name, args.every, len(keys), len(held), args.voxel_size),
              "",
              "%s, commit %s, %s" % (machine_line(), git_commit() or "?",
                                     datetime.datetime.now(datetime.timezone.utc)
                                     .strftime("%Y-%m-%d %H:%M UTC"))]
    notes = ["mesh samples seen by a held-out view: %s of %d; 'precision, unculled' counts "
             "every sample (surfaces no held-out view shows count as errors)"
             % (", ".join("%s %.2f" % (system, r["seen_fraction"]) for system, r in rows),
                SAMPLES)]
    lod = [r for system, r in rows if system.startswith("plenox LOD")]
    if lod:
        full = rows[0][1]
        notes.append("level of detail: %d of %d triangles (%.1f %%), simplification error %.1f mm "
                     "(reported by plenox), GLB %.2f MB against %.2f MB for the full mesh's GLB; "
                     "F-score @2 cm %.3f against %.3f (difference %+.3f), Chamfer %+.2f cm"
                     % (lod[0]["triangles"], full["triangles"],
                        100.0 * lod[0]["triangles"] / full["triangles"],
                        1000 * lod[0]["lod_error_m"], lod[0]["glb_bytes"] / 1e6,
                        lod[0]["full_glb_bytes"] / 1e6, lod[0]["fscore"], full["fscore"],
                        lod[0]["fscore"] - full["fscore"],
                        lod[0]["chamfer_cm"] - full["chamfer_cm"]))
    write_report(render_table(cols, body, header, notes), args.out)


if __name__ == "__main__":
    main()

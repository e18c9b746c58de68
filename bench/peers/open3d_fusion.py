#!/usr/bin/python3
"""Open3D peer for `holoport-bench fusion`: TSDF fusion + mesh extraction of
the exact depth (and colour) images our fusion got, written by the bench.

Usage: /usr/bin/python3 open3d_fusion.py DIR --voxel V --trunc T [--depth-max M] [--repeats R]

DIR/cameras.json:
  {"pods": [{"width": W, "height": H, "fx": .., "fy": .., "cx": .., "cy": ..,
             "extrinsic": [16 numbers, row-major 4x4 camera_from_world]}, ...],
   "frames": N}
DIR/frame_<fff>/pod<k>_depth.png  uint16 millimetres, 0 = unused (already masked)
DIR/frame_<fff>/pod<k>_color.png  RGB8, same size as the depth

Per frame and repeat: a fresh ScalableTSDFVolume (voxel_length = V,
sdf_trunc = T, RGB8 colour), integrate every pod, extract_triangle_mesh.
Integrate and extract are timed separately with time.perf_counter; image
loading and RGBDImage creation are outside the timed region. The mesh of the
first repeat is written to DIR/open3d_frame_<fff>.ply.
Prints one JSON object on stdout. Exit code 3 if open3d cannot be imported.
"""
import argparse
import json
import os
import sys
import time


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--voxel", type=float, required=True)
    ap.add_argument("--trunc", type=float, required=True)
    ap.add_argument("--depth-max", type=float, default=5.0)
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    try:
        import numpy as np
        import open3d as o3d
    except ImportError as e:
        print(json.dumps({"error": "open3d not importable: %s" % e}))
        return 3

    with open(os.path.join(args.dir, "cameras.json")) as f:
        cams = json.load(f)
    pods = cams["pods"]
    intrinsics, extrinsics = [], []
    for p in pods:
        intrinsics.append(o3d.camera.PinholeCameraIntrinsic(p["width"], p["height"], p["fx"], p["fy"], p["cx"], p["cy"]))
        extrinsics.append(np.array(p["extrinsic"], dtype=np.float64).reshape(4, 4))

    out = {"open3d_version": o3d.__version__, "volume": "ScalableTSDFVolume", "frames": []}
    for fi in range(int(cams["frames"])):
        fdir = os.path.join(args.dir, "frame_%03d" % fi)
        rgbds = []
        for k in range(len(pods)):
            color = o3d.io.read_image(os.path.join(fdir, "pod%d_color.png" % k))
            depth = o3d.io.read_image(os.path.join(fdir, "pod%d_depth.png" % k))
            rgbds.append(o3d.geometry.RGBDImage.create_from_color_and_depth(
                color, depth, depth_scale=1000.0, depth_trunc=args.depth_max, convert_rgb_to_intensity=False))
        integrate_ms, extract_ms = [], []
        for r in range(args.repeats):
            t0 = time.perf_counter()
            vol = o3d.pipelines.integration.ScalableTSDFVolume(
                voxel_length=args.voxel, sdf_trunc=args.trunc,
                color_type=o3d.pipelines.integration.TSDFVolumeColorType.RGB8)
            for k in range(len(pods)):
                vol.integrate(rgbds[k], intrinsics[k], extrinsics[k])
            t1 = time.perf_counter()
            mesh = vol.extract_triangle_mesh()
            t2 = time.perf_counter()
            integrate_ms.append(1000.0 * (t1 - t0))
            extract_ms.append(1000.0 * (t2 - t1))
            if r == 0:
                ply = os.path.join(args.dir, "open3d_frame_%03d.ply" % fi)
                o3d.io.write_triangle_mesh(ply, mesh, write_ascii=False)
                ntri = len(mesh.triangles)
        out["frames"].append({"frame": fi, "integrate_ms": integrate_ms, "extract_ms": extract_ms,
                              "ply": ply, "triangles": ntri})
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())

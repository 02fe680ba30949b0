# paraview_bench.py — the ParaView side of the rendering comparison in `make bench`
# (tests/bench/bench_render.sh). A pvbatch script; ParaView is never a build or test dependency.
#
#   pvbatch paraview_bench.py FILE.ply [--frames N] [--size WxH] [--radius R]
#                             [--default-frames M]
#   (under xvfb-run when pvbatch needs an X display, as Debian's build does)
#
# Loads FILE with ParaView's PLY reader plus Convert To Point Cloud (a face-less PLY has no
# cells, and the Points representation draws nothing without vertex cells), shows it in a
# Render View of the given size (default 1280x720) coloured by the file's RGB without a colour
# map (like splatd), orientation axes hidden, camera reset to frame the cloud. Per
# representation it times N + 1 still renders, turning the camera 0.5 degrees (Azimuth) before
# each so that nothing is cached; the first is a warm-up (shader compile, data upload) and is
# not counted. Each timed render ends with the render window's WaitForCompletion (glFinish),
# as splatd's frame time ends with glFinish. Representations:
#   Points                  point size 1, no spheres (the counterpart of splatd's `points`);
#   Point Gaussian matched  GaussianRadius = R (--radius: splatd's median splat radius of the
#                           same cloud), default shader preset; only when R is given;
#   Point Gaussian          ParaView's own default radius (0.005 x the data's largest extent),
#                           timed over M frames (default N): on a 100 m scene that radius is
#                           0.5 m, ten times splatd's splats, and a frame takes seconds.
# Prints on stdout:
#   "paraview: ParaView <version>, <OpenGL renderer>, <n> points"
#   "pv: | <representation> | <radius or -> | <median ms> | <min ms> |"   one row each.
import statistics
import sys
import time

import paraview.simple as pvs
from paraview.simple import (ColorBy, GetActiveViewOrCreate, GetParaViewSourceVersion,
                             Hide, PLYReader, Render, ResetCamera, Show)


def parse_args(argv):
    """Returns (file, frames, default_frames, width, height, radius or None); exits with
    status 2 on bad input."""
    args = {"frames": 10, "default_frames": None, "size": (1280, 720), "radius": None,
            "file": None}
    i = 0
    try:
        while i < len(argv):
            a = argv[i]
            if a == "--frames":
                args["frames"] = int(argv[i + 1])
                if not 1 <= args["frames"] <= 1000:
                    raise ValueError("--frames must be in 1-1000")
                i += 2
            elif a == "--default-frames":
                args["default_frames"] = int(argv[i + 1])
                if not 1 <= args["default_frames"] <= 1000:
                    raise ValueError("--default-frames must be in 1-1000")
                i += 2
            elif a == "--size":
                w, h = argv[i + 1].lower().split("x")
                args["size"] = (int(w), int(h))
                i += 2
            elif a == "--radius":
                args["radius"] = float(argv[i + 1])
                if not args["radius"] > 0:
                    raise ValueError("--radius must be positive")
                i += 2
            elif args["file"] is None and not a.startswith("--"):
                args["file"] = a
                i += 1
            else:
                raise ValueError("unexpected argument '%s'" % a)
        if args["file"] is None:
            raise ValueError("no FILE given")
    except (ValueError, IndexError) as e:
        sys.stderr.write("paraview_bench: %s\nusage: pvbatch paraview_bench.py FILE.ply "
                         "[--frames N] [--size WxH] [--radius R] [--default-frames M]\n" % e)
        sys.exit(2)
    return (args["file"], args["frames"], args["default_frames"] or args["frames"],
            args["size"][0], args["size"][1], args["radius"])


def time_renders(view, frames):
    """Renders frames + 1 times, turning the camera 0.5 degrees before each; returns the
    times in ms of all but the first render."""
    cam = view.GetActiveCamera()
    window = view.GetRenderWindow()
    times = []
    for i in range(frames + 1):
        cam.Azimuth(0.5)
        t0 = time.perf_counter()
        Render(view)
        # glFinish: without it the GL driver may still be rasterising when Render returns (on
        # llvmpipe the queued work can even be dropped by the next frame's clear), and
        # splatd's frame time includes its glFinish too.
        window.WaitForCompletion()
        t1 = time.perf_counter()
        if i > 0:
            times.append((t1 - t0) * 1e3)
    return times


def main():
    path, frames, default_frames, width, height, radius = parse_args(sys.argv[1:])
    reader = PLYReader(FileNames=[path])
    # A PLY file without faces reads as points with no cells, which the Points representation
    # does not draw at all (an empty image in 8 ms); give every point a vertex. Point Gaussian
    # draws the points either way.
    if hasattr(pvs, "ConvertToPointCloud"):
        source = pvs.ConvertToPointCloud(Input=reader)
    else:
        source = pvs.MaskPoints(Input=reader, OnRatio=1, GenerateVertices=1,
                                MaximumNumberofPoints=2**31 - 1)
    source.UpdatePipeline()
    info = source.GetDataInformation()
    npts = info.GetNumberOfPoints()
    view = GetActiveViewOrCreate("RenderView")
    view.ViewSize = [width, height]
    view.OrientationAxesVisibility = 0
    disp = Show(source, view)
    arrays = [a.GetName() for a in source.PointData]
    if "RGB" in arrays:
        ColorBy(disp, ("POINTS", "RGB"))
        disp.MapScalars = 0
    ResetCamera(view)
    Render(view)
    renderer = "unknown renderer"
    for line in view.GetRenderWindow().ReportCapabilities().splitlines():
        if "renderer string" in line:
            renderer = line.split(":", 1)[1].strip()
    print("paraview: ParaView %s, %s, %d points"
          % (GetParaViewSourceVersion().replace("paraview version ", ""), renderer, npts))
    sys.stdout.flush()

    runs = [("Points", None, frames)]
    if radius is not None:
        runs.append(("Point Gaussian matched", radius, frames))
    disp.SetRepresentationType("Point Gaussian")
    runs.append(("Point Gaussian", disp.GaussianRadius, default_frames))
    for name, r, n in runs:
        if name == "Points":
            disp.SetRepresentationType("Points")
            disp.PointSize = 1.0
            disp.RenderPointsAsSpheres = 0
        else:
            disp.SetRepresentationType("Point Gaussian")
            disp.GaussianRadius = r
        times = time_renders(view, n)
        print("pv: | %s | %s | %.1f | %.1f |" % (name, "-" if r is None else "%.4g" % r,
                                                statistics.median(times), min(times)))
        sys.stdout.flush()
    Hide(source, view)


main()

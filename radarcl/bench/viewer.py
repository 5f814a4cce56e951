"""`radarcl bench viewer`: the volume renderer on the paper's full grid (800 x 700 x 200 at
0.1 m) at 512 x 512 through EGL, against a plain fixed-step ray march in the same run.

The plain march is the same shader without empty-space skipping: the same samples (one per
voxel of length), the same transfer function, so the two pictures must be identical and the
bench checks that they are (``max_pixel_diff``). A second plain march at 256 samples per ray
is the baseline ARCHITECTURE.md measured (149 ms); it undersamples a 1,080-voxel diagonal
and can miss a one-voxel surface, so it is listed, not compared.

The map: by default the reference scene's ground truth as a fused map would hold it, built
in a few seconds with numpy: surfaces (OCCUPIED voxels) at +3 nat and free air at -1 nat inside
the radar's field of view (64 deg x 64 m from the stand), unseen elsewhere. The grass surface
spans the whole fan, so the occupied part is not a small box. ``--map`` times a real map file.
"""

import numpy as np

from radarcl import logodds
from radarcl.bench.timing import interleaved_medians
from radarcl.viewer.camera import Camera
from radarcl.viewer.headless import time_frames
from radarcl.viewer.modes import Settings
from radarcl.viewer.renderer import Renderer, create_context, read_rgb
from radarcl.viewer.volume import from_units, load_map

SIZE = (512, 512)
OCCUPIED_NATS, FREE_NATS = 3.0, -1.0
FOV_HALF_DEG, RANGE_M = 32.0, 64.0


def scene_volume(voxel_m=0.1, max_size=2048):
    """The reference scene's truth as a map would hold it (see the module docstring)."""
    from radarcl.scene.outdoor import OCCUPIED, paper_grid, paper_scene

    spec = paper_grid(voxel_m)
    truth = paper_scene().truth(spec)
    nz, ny, nx = spec.array_shape
    x = spec.origin_m[0] + (np.arange(nx) + 0.5) * voxel_m
    y = spec.origin_m[1] + (np.arange(ny) + 0.5) * voxel_m
    r = np.hypot(x[None, :], y[:, None])
    seen = (r < RANGE_M) & (np.abs(np.degrees(np.arctan2(y[:, None], x[None, :]))) < FOV_HALF_DEG)
    units = np.where(truth == OCCUPIED, np.int32(OCCUPIED_NATS * logodds.SCALE),
                     np.where(truth == 0, np.int32(FREE_NATS * logodds.SCALE), np.int32(0)))
    units *= seen[None, :, :]
    return from_units(spec, units, max_size)


def run(map_path=None, repeat=6, modes=("occupancy", "mip", "iso"), report=None):
    """Time every ray-marched mode skipping vs plain, and the sphere mode; returns a dict whose
    ``ms_per_frame`` / ``naive_ms_per_frame`` are the occupancy mode's."""
    import time

    say = report or (lambda line: None)
    ctx = create_context()
    max_size = int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"])
    start = time.perf_counter()
    volume = load_map(map_path, max_size) if map_path else scene_volume(max_size=max_size)
    prepare_s = time.perf_counter() - start
    say(f"map {volume.spec.shape} ready in {prepare_s:.1f} s; uploading ...")
    start = time.perf_counter()
    renderer = Renderer(ctx, volume)
    ctx.finish()
    upload_ms = (time.perf_counter() - start) * 1e3
    camera = Camera.fit(volume.spec)
    fbo = renderer.framebuffer(SIZE)
    result = dict(renderer=ctx.info["GL_RENDERER"], gl_version=ctx.info["GL_VERSION"], size=list(SIZE),
                  grid=list(volume.spec.shape), map=map_path or "reference scene truth (synthetic map)",
                  prepare_s=prepare_s, upload_ms=upload_ms, repeat=repeat, modes={})
    for name in modes:
        skip, naive = Settings(skip=True), Settings(skip=False)

        def frame(settings, name=name):
            renderer.render(camera, name, settings, SIZE)
            ctx.finish()

        fbo.use()
        say(f"{name}: timing skipping and the plain march ...")
        t = interleaved_medians({"skip": lambda: frame(skip), "naive": lambda: frame(naive)},
                                repeat=repeat, block=2, warmup=1)
        frame(skip)
        a = read_rgb(fbo).astype(int)
        frame(naive)
        b = read_rgb(fbo).astype(int)
        result["modes"][name] = dict(ms_per_frame=t["skip"] * 1e3, naive_ms_per_frame=t["naive"] * 1e3,
                                     ratio_vs_naive=t["naive"] / t["skip"], max_pixel_diff=int(np.abs(a - b).max()),
                                     lit_pixels=int((a != a[0, 0]).any(axis=-1).sum()))
    plain256 = Settings(skip=False, step=float(np.linalg.norm(volume.spec.shape)) / 256)
    result["naive256_ms_per_frame"], _, _ = time_frames(renderer, camera, "occupancy", plain256, SIZE,
                                                        repeat=max(2, repeat // 2))
    say("spheres ...")
    ms, _, _ = time_frames(renderer, camera, "spheres", Settings(), SIZE, repeat=max(2, repeat // 2))
    result["modes"]["spheres"] = dict(ms_per_frame=ms, instances=renderer.sphere_count)
    result["update"] = _time_update(ctx, renderer)
    main = result["modes"].get("occupancy") or next(iter(result["modes"].values()))
    result.update(ms_per_frame=main["ms_per_frame"], naive_ms_per_frame=main.get("naive_ms_per_frame"),
                  ratio_vs_naive=main.get("ratio_vs_naive"))
    return result


def _time_update(ctx, renderer, n_bricks=4096):
    """Milliseconds to write ``n_bricks`` changed 8^3 bricks (texture and coarse levels), as a
    live view does while fusion runs, against re-uploading the whole volume."""
    import time

    volume = renderer.volume
    spec = volume.spec
    rng = np.random.default_rng(0)
    bricks = np.stack([rng.integers(0, n, n_bricks) for n in spec.brick_shape], axis=1)
    nz, ny, nx = spec.array_shape
    boxes = [((bz * 8, min(bz * 8 + 8, nz)), (by * 8, min(by * 8 + 8, ny)), (bx * 8, min(bx * 8 + 8, nx)))
             for bx, by, bz in bricks.tolist()]
    lo, hi = bricks.min(axis=0), bricks.max(axis=0) + 1
    start = time.perf_counter()
    renderer.update(boxes, (tuple(lo), tuple(hi)))
    ctx.finish()
    partial = (time.perf_counter() - start) * 1e3
    start = time.perf_counter()
    renderer.upload(volume)
    ctx.finish()
    full = (time.perf_counter() - start) * 1e3
    return dict(bricks=n_bricks, partial_ms=partial, full_upload_ms=full)


def format_table(result):
    """Human-readable lines for a ``run`` result."""
    lines = [f"viewer: {result['map']}, grid {' x '.join(map(str, result['grid']))}, "
             f"{result['size'][0]} x {result['size'][1]} px on {result['renderer']} ({result['gl_version']})",
             f"  upload {result['upload_ms']:.0f} ms (map prepared in {result['prepare_s']:.1f} s)",
             f"  {'mode':10s} {'ms/frame':>9s} {'plain ms':>9s} {'ratio':>7s} {'pixel diff':>10s}"]
    for name, m in result["modes"].items():
        if "naive_ms_per_frame" in m:
            lines.append(f"  {name:10s} {m['ms_per_frame']:9.1f} {m['naive_ms_per_frame']:9.1f} "
                         f"{m['ratio_vs_naive']:7.1f} {m['max_pixel_diff']:10d}")
        else:
            lines.append(f"  {name:10s} {m['ms_per_frame']:9.1f}   ({m['instances']} instances)")
    u = result["update"]
    lines += [f"  plain march at 256 samples per ray (ARCHITECTURE.md's baseline): "
              f"{result['naive256_ms_per_frame']:.1f} ms",
              f"  partial update of {u['bricks']} bricks {u['partial_ms']:.1f} ms vs full upload "
              f"{u['full_upload_ms']:.0f} ms",
              f"  ms_per_frame {result['ms_per_frame']:.1f} (occupancy; goal <= 50 on llvmpipe), "
              f"ratio_vs_naive {result['ratio_vs_naive']:.1f}"]
    return lines



def add_arguments(parser):
    """`radarcl bench viewer` options."""
    from radarcl.commands.options import bounded_int

    parser.add_argument("--repeat", type=bounded_int(1, 100), default=6,
                        help="timed frames per mode, 1-100 (default: %(default)s)")
    parser.add_argument("--map", default=None, help="time this map file instead of the reference scene's truth")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    result = run(args.map, repeat=args.repeat, report=say)
    return result, format_table(result)

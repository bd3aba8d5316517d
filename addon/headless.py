"""Radiosity from the command line, with bpy and no UI.

From the repository root (Blender as a Python module):

    python -m addon.headless SCENE.blend [--out LIT.blend] [--render IMAGE.png] [options]

(`--lightmap` and `--refine` take any number of object names: put them after SCENE.blend.)

or inside a Blender binary:

    blender -b SCENE.blend --python addon/run_in_blender.py -- [--out LIT.blend] [--render IMAGE.png] [...]

Prints the progress of each stage (a bar on a terminal, plain lines in a pipe or log) and the
time of each stage, writes the lit .blend (results as colour attributes with the emission-only
"Radiosity View" material), exports glTF (`--gltf`, the attribute as COLOR_0) and renders a PNG
with Cycles on the CPU. The view material is emission only, so a few samples and no light
bounces suffice. Errors are one line on stderr,
starting with "error:", and the exit code says which kind (`EXIT_CODES`, listed in --help);
warnings (e.g. each object skipped because it cannot take part) are lines on stderr starting
with "warning:".
"""

import argparse
import math
import os
import sys
import time

import bpy

from . import console, outputs, pipeline, register, results, solve

EXIT_OK = 0
EXIT_SCENE = 1
EXIT_USAGE = 2
EXIT_INPUT = 3
EXIT_OUTPUT = 4
EXIT_CANCELLED = 130
EXIT_CODES = {
    EXIT_OK: "success",
    EXIT_SCENE: "the scene cannot be lit (nothing to light or no emitters; objects that cannot take "
    "part are named: elsewhere they are skipped with a warning on stderr)",
    EXIT_USAGE: "bad command line, or --render without a scene camera",
    EXIT_INPUT: "the scene file is missing, unreadable or not a .blend file",
    EXIT_OUTPUT: "the lit .blend or the image could not be written",
    EXIT_CANCELLED: "interrupted (Ctrl+C)",
}

# object types whose results --lightmap / --refine without names apply to
RESULT_TYPES = {"MESH", "SURFACE", "CURVE", "FONT", "META"}
# a .blend starts with "BLENDER", or is gzip (Blender < 3.0) or zstd (3.0 and later) compressed
BLEND_MAGIC = (b"BLENDER", b"\x1f\x8b", b"\x28\xb5\x2f\xfd")


class HeadlessError(Exception):
    """A failure reported as one line and an exit code."""

    def __init__(self, message, code):
        super().__init__(message)
        self.code = code


def parse_args(argv, scene_required=True):
    epilog = "exit codes:\n" + "\n".join(f"  {code:<4} {text}" for code, text in EXIT_CODES.items())
    parser = argparse.ArgumentParser(
        prog="python -m addon.headless",
        description=__doc__.splitlines()[0],
        epilog=epilog,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("scene", nargs=None if scene_required else "?", help="the .blend file to light")
    parser.add_argument("--out", help="write the lit scene to this .blend")
    parser.add_argument("--render", help="render the lit scene with Cycles (CPU) to this PNG")
    parser.add_argument(
        "--gltf", help="export the lit scene to this .gltf or .glb (the Radiosity attribute as COLOR_0)"
    )
    parser.add_argument("--quality", choices=sorted(pipeline.QUALITY_TOLERANCE), help="tolerance preset")
    positive, count, whole = _positive(float), _positive(int), _positive(int, zero=True)
    parser.add_argument("--tol", type=positive, help="relative solver tolerance (overrides --quality)")
    parser.add_argument("--max-bounces", type=whole, help="stop after this many bounces (0: until converged)")
    parser.add_argument("--no-occlusion", action="store_true", help="ignore shadows between surfaces")
    parser.add_argument(
        "--method",
        choices=("auto", "pairs", "hierarchical"),
        help="solver: every pair of patches, links and sub-patches at contacts and seams, or auto "
        "(hierarchical when lightmaps or refined twins are baked; default: the scene's)",
    )
    parser.add_argument("--samples", type=count, default=8, help="Cycles samples for --render (default 8)")
    parser.add_argument("--resolution", type=count, nargs=2, metavar=("W", "H"), help="render size in pixels")
    parser.add_argument(
        "--lightmap",
        nargs="*",
        metavar="OBJECT",
        help="also bake a lightmap for these objects (none named: every object that gets results)",
    )
    parser.add_argument("--lightmap-size", type=count, help="lightmap texels per side (default: by density)")
    parser.add_argument("--texels-per-metre", type=positive, help="lightmap density when no size is given")
    parser.add_argument("--lightmap-uv", help="UV map to bake through (default: generate one)")
    parser.add_argument(
        "--lightmap-tol", type=_positive(float, zero=True), help="interpolation tolerance (0: every texel)"
    )
    parser.add_argument(
        "--refine",
        nargs="*",
        metavar="OBJECT",
        help="show these objects' results on refined twins (none named: every object that gets results)",
    )
    parser.add_argument("--refine-tol", type=positive, help="relative tolerance of the refined twins")
    parser.add_argument("--min-edge", type=positive, help="shortest edge of the refined twins (m)")
    parser.add_argument(
        "--max-edge", type=_positive(float, zero=True), help="split every longer edge (m; 0: none)"
    )
    return parser.parse_args(argv)


def apply_output_options(args, scene):
    """Set the objects' output properties from --lightmap / --refine (and their options).

    Raises
    ------
    HeadlessError
        EXIT_USAGE if a named object does not exist, or is named for both outputs.
    """
    if args.lightmap_size is not None and args.lightmap_size > outputs.MAX_SIZE:
        raise HeadlessError(f"--lightmap-size {args.lightmap_size} is above {outputs.MAX_SIZE}", EXIT_USAGE)
    chosen = {}
    for option, output in (("lightmap", "LIGHTMAP"), ("refine", "REFINED")):
        names = getattr(args, option)
        if names is None:
            continue
        if not names:
            names = [obj.name for obj in scene.objects if obj.type in RESULT_TYPES]
        for name in names:
            obj = scene.objects.get(name)
            if obj is None:
                raise HeadlessError(f"--{option}: the scene has no object named {name!r}", EXIT_USAGE)
            if chosen.get(name, output) != output:
                raise HeadlessError(f"{name!r} is named for both --lightmap and --refine", EXIT_USAGE)
            chosen[name] = output
    for name, output in chosen.items():
        obj = scene.objects[name]
        obj.curved_radiosity_output = output
        if args.lightmap_size is not None:
            obj.curved_radiosity_lightmap_size = args.lightmap_size
        if args.texels_per_metre is not None:
            obj.curved_radiosity_texels_per_metre = args.texels_per_metre
        if args.lightmap_uv is not None:
            obj.curved_radiosity_lightmap_uv = args.lightmap_uv
        if args.lightmap_tol is not None:
            obj.curved_radiosity_lightmap_tol = args.lightmap_tol
        if args.refine_tol is not None:
            obj.curved_radiosity_refine_tol = args.refine_tol
        if args.min_edge is not None:
            obj.curved_radiosity_refine_min_edge = args.min_edge
        if args.max_edge is not None:
            obj.curved_radiosity_refine_max_edge = args.max_edge


def _positive(kind, zero=False):
    """An argparse type: a finite number of `kind` above zero (or at least zero)."""

    def convert(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number of type {kind.__name__}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} must be a finite number")
        if value < 0 or (value == 0 and not zero):
            bound = "at least 0" if zero else "above 0"
            raise argparse.ArgumentTypeError(f"{text!r} must be {bound}")
        return value

    convert.__name__ = kind.__name__  # argparse names the type in its messages
    return convert


def open_scene(path):
    """Open a .blend file, or raise HeadlessError(EXIT_INPUT) saying why it cannot be opened."""
    if not os.path.exists(path):
        raise HeadlessError(f"scene file {path!r} does not exist", EXIT_INPUT)
    if not os.path.isfile(path):
        raise HeadlessError(f"scene file {path!r} is not a file", EXIT_INPUT)
    try:
        with open(path, "rb") as stream:
            head = stream.read(7)
    except OSError as error:
        reason = error.strerror or error
        raise HeadlessError(f"cannot read scene file {path!r}: {reason}", EXIT_INPUT) from None
    if not head.startswith(BLEND_MAGIC):
        raise HeadlessError(f"{path!r} is not a .blend file", EXIT_INPUT)
    try:
        bpy.ops.wm.open_mainfile(filepath=path)
    except RuntimeError as error:
        raise HeadlessError(f"cannot open {path!r}: {_first_line(error)}", EXIT_INPUT) from None


def _first_line(error):
    text = str(error).strip().splitlines()
    line = text[0] if text else type(error).__name__
    return line.removeprefix("Error: ")


def settings(args, scene):
    """Solver settings: the scene's own, overridden by the command line."""
    base = pipeline.settings_from_scene(scene)
    tol = args.tol or (pipeline.QUALITY_TOLERANCE[args.quality] if args.quality else base.tol)
    bounces = base.max_bounces if args.max_bounces is None else (args.max_bounces or None)
    return solve.Settings(
        tol=tol,
        occlusion=base.occlusion and not args.no_occlusion,
        max_bounces=bounces,
        method=args.method or base.method,
    )


def render(scene, path, samples, resolution):
    """Render `scene` with Cycles on the CPU to a PNG."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 0
    if resolution:
        scene.render.resolution_x, scene.render.resolution_y = resolution
        scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)


def export_gltf(path):
    """Export the rendered objects with Blender's bundled glTF exporter, the `Radiosity`
    attribute as each primitive's COLOR_0 (.glb: binary, otherwise .gltf with a .bin beside it).
    Only renderable objects go out, so a twin's hidden original is not exported twice."""
    binary = path.lower().endswith(".glb")
    bpy.ops.export_scene.gltf(
        filepath=path,
        export_format="GLB" if binary else "GLTF_SEPARATE",
        use_renderable=True,
        export_vertex_color="NAME",
        export_vertex_color_name=results.FRONT,
    )


def main(argv=None, scene_loaded=False):
    """Run the pipeline; returns the process exit code (`EXIT_CODES`)."""
    args = parse_args(sys.argv[1:] if argv is None else argv, scene_required=not scene_loaded)
    try:
        return run(args)
    except HeadlessError as error:
        print(f"error: {error}", file=sys.stderr)
        return error.code
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return EXIT_CANCELLED


def run(args):
    """Load, light, save and render as `args` say; raises HeadlessError on failure."""
    times = {}
    start = time.perf_counter()
    if args.scene:
        open_scene(args.scene)
    if not hasattr(bpy.types.Scene, "curved_radiosity"):
        register()
    times["load"] = time.perf_counter() - start
    scene = bpy.context.scene
    if args.render and scene.camera is None:
        raise HeadlessError("--render needs a scene camera", EXIT_USAGE)
    apply_output_options(args, scene)
    print(f"Radiosity for {bpy.data.filepath or 'the current scene'}")
    progress = console.ConsoleProgress()
    try:
        job = pipeline.compute(bpy.context, settings(args, scene), progress=progress)
    except pipeline.PipelineError as error:
        raise HeadlessError(str(error), EXIT_SCENE) from None
    finally:
        progress.close()
    for warning in job.collected.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    times.update(job.times)
    if args.out:
        start = time.perf_counter()
        path = os.path.abspath(args.out)
        _output(lambda: bpy.ops.wm.save_as_mainfile(filepath=path, copy=True), path)
        times["save"] = time.perf_counter() - start
    if args.gltf:
        start = time.perf_counter()
        path = os.path.abspath(args.gltf)
        _output(lambda: export_gltf(path), path)
        top = results.brightest()
        if top > 1.0:
            print(
                f"warning: glTF stores colours as fractions: radiance above 1 (up to {top:.3g}) is "
                "clamped in COLOR_0; lower the lights' power to keep it",
                file=sys.stderr,
            )
        times["gltf"] = time.perf_counter() - start
    if args.render:
        start = time.perf_counter()
        path = os.path.abspath(args.render)
        _output(lambda: render(scene, path, args.samples, args.resolution), path)
        times["render"] = time.perf_counter() - start
    print(pipeline.summary(job))
    print("stage times (s):  " + "  ".join(f"{k} {v:.3f}" for k, v in times.items()))
    if job.solution.stats:
        print("solver stats:     " + "  ".join(f"{k} {_fmt(v)}" for k, v in job.solution.stats.items()))
    return EXIT_OK


def _output(write, path):
    """write() into `path` (its folder created as needed); HeadlessError(EXIT_OUTPUT) if it fails."""
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        write()
    except (OSError, RuntimeError) as error:
        raise HeadlessError(f"cannot write {path!r}: {_first_line(error)}", EXIT_OUTPUT) from None


def _fmt(value):
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_fmt(v)}" for k, v in value.items()) + "}"
    return f"{value:.3f}" if isinstance(value, float) else str(value)


if __name__ == "__main__":
    sys.exit(main())

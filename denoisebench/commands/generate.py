"""Generate a dataset: procedural scenes (and your own USD stages) rendered into noisy/reference EXR sequences.

For every scene: OUT/<scene>/scene.usda (+ textures), OUT/<scene>/sppNNNN/frame_NNNN.exr (noisy
buffers, features and variances at each --spp), OUT/<scene>/reference/frame_NNNN.exr (reference
color and its variance), and OUT/dataset.json (config, render plans, splits, per-frame sha256, render
seconds, reference quality). Frame i is rendered at the camera's i-th time sample.

The --spp rungs of a frame are nested: the k-spp image is the mean of the first k samples of one
progressive render per pixel, so --spp 1,2,4,...,64 costs about what --spp 64 costs and rung 4 is
the same bytes as a plain --spp 4 dataset with the same seed (rungs are correlated; each is
unbiased). A rung's render seconds is the time the progressive render took to reach it.
--independent-rungs renders every rung on its own instead (recorded in dataset.json's config).

References are adaptive: each frame's reference is rendered in rounds (fresh deterministic seeds)
until its noise floor -- the relMSE a perfect denoiser would score against it, estimated robustly
against fireflies -- is at most --ref-error, with --ref-spp as the cap; frames that stop at the cap
are named in a warning. --ref-error 0 renders exactly --ref-spp samples instead. The manifest
records per frame the spp used, the seconds and the floor reached.

Light transport is complete (unbounded depth, Russian roulette as Mitsuba's path integrator) unless
--max-depth N restricts it (or the stage's customLayerData denoisebench maxDepth); the manifest
records the restriction and who asked for it.

Running the same command again resumes where it stopped and gives the same bytes as an
uninterrupted run (also after Ctrl-C or SIGTERM: exit 130 within 2 s, no frame counted as failed);
a different config in the same OUT is refused unless --force. A non-empty OUT that is not a
dataset is refused too; with --force the dataset is written beside the files there, none of which
it touches. The executor is
not part of the config: --executor ray gives the same bytes as the local executor.

--usd FILE copies the stage and the files it depends on into OUT/usd_<stem>/ (those outside its folder, as
production assets lay them out, under files/ with the stage's paths rewritten, so the copy renders
anywhere) and renders it along its own time codes: all of them by default (a stage of more than
300 gets a note saying how many), --time-range START:END a window of them, --frames N that many
evenly spaced (first and last included); the choice is written into the copy's customLayerData and
recorded in dataset.json (frame_selection).
Every --usd file is checked before anything is written: a missing or malformed stage, or one
without a camera (give --camera PATH or --auto-camera), without a light (--default-light) or with
nothing renderable, refuses the command (one line, exit 2). --auto-camera's orbit (over --frames
frames when the stage has no time range) and --default-light's lights are written into the copied
OUT/usd_<stem>/scene.usda.

--mitsuba FILE (alias --xml) loads a Mitsuba 3 scene file with Mitsuba and renders it from its first
sensor (perspective, thinlens or orthographic) held still over --frames frames, with effects inferred
from its plugins; other sensors are refused (exit 2). --auto-camera gives it the orbit --usd stages get
(around its bounding box, +Y up) instead of its sensor. Its files are found as Mitsuba finds them
(<path> directives, the scene's folder, then --mitsuba-path DIR as Mitsuba's -a; they may lie anywhere)
and copied into OUT/xml_<stem>/: scene.xml (<path>s removed, names that leave its folder moved under
files/, parameters written in as <default>s) loads on another machine with no options. --define
NAME=VALUE (repeatable, Mitsuba's -D) sets its $parameters; $spp and the film size ($res, $resx, $resy)
need none: denoisebench sets its own. Its integrator's restriction is honoured and recorded: a
path-family max_depth, and `direct` (read through wrappers such as moment and aov) as direct
illumination only (max_depth 2); --max-depth wins; another integrator gets a warning.

--scene-list FILE --root DIR renders the scenes a scene list names (TOML: source usd or mitsuba, a path
under DIR, camera orbit or own, defines, licence, where to get it; generator/scene_lists.py), as if each
were given with --usd/--mitsuba; shipped lists (denoisebench/scenes/lists/) are named without their
folder. A scene missing under DIR is one line naming the repository to clone (exit 2).

Exit codes: 0 done, 2 bad input (one line, nothing written), 1 some frames failed to render
(reported; the dataset is left resumable and marked incomplete).
"""

from __future__ import annotations

import sys
from pathlib import Path

from denoisebench.dataset import disk_space
from denoisebench.errors import UserInputError
from denoisebench.generator.dataset_run import (
    DEFAULT_REF_ERROR,
    DEFAULT_REF_SPP,
    REFERENCE_SPP_FACTOR,
    GenerateRequest,
    check_out_folder,
    generate_dataset,
    validate_request,
)
from denoisebench.generator.executors import make_executor
from denoisebench.generator.mitsuba_xml_structure import parse_defines
from denoisebench.outputs import check_writable_dir
from denoisebench.scenes import list_families

EPILOG = """examples:
  generate-dataset --out data/small --families cornell,glossy_fireflies --scenes 2 --frames 4 \\
      --width 128 --height 128 --spp 1,4,16 --ref-spp 1024
  generate-dataset --out data/ladder --families cornell --spp 1,2,4,8,16,32,64   # nested rungs
  generate-dataset --out data/uncorrelated --families cornell --spp 1,4,16 --independent-rungs
  denoisebench generate --out data/mine --usd shots/my_shot.usda --spp 4 --ref-spp 512
  generate-dataset --out data/clean --families cornell --ref-error 2e-4 --ref-spp 16384
  generate-dataset --out data/direct --families cornell --max-depth 2 --ref-error 0 --ref-spp 1024
  generate-dataset --out data/big --scenes 20 --executor ray --ray-address auto
  generate-dataset --out data/tp --scene-list mitsuba_docs --root mitsuba-data --frames 2 --width 64 --height 64
  generate-dataset --out data/tp_usd --scene-list usd_wg_assets --root assets --frames 2 --spp 1,4,16
  generate-dataset --out data/asset --usd asset.usdz --auto-camera --default-light --frames 8 --spp 4
  generate-dataset --out data/shot --usd shot.usda --time-range 100:400 --frames 12   # 12 of its time codes
  generate-dataset --out data/bitterli --mitsuba staircase/scene_v3.xml --frames 4 --spp 1,4 --ref-spp 1024
  generate-dataset --out data/docs --mitsuba mitsuba-data/docs/scenes/sensor_thinlens.xml --frames 1
  generate-dataset --out data/ortho --mitsuba mitsuba-data/docs/scenes/sensor_orthographic.xml \\
      --mitsuba-path mitsuba-data/common --frames 1   # a scene written for Mitsuba's -a
  generate-dataset --out data/mts --mitsuba mitsuba-data/tests/scenes/floating_sphere/test_directional_direct.xml \\
      --define integrator=path --frames 1   # the scene's $integrator: path instead of its default, direct

documentation:
  docs/datasets.md    nested --spp ladders and --independent-rungs, datasets of 10 000 frames
  docs/references.md  --ref-error, --ref-spp, --max-depth: full transport and adaptive references
  docs/scenes.md      --usd, --camera, --auto-camera, --default-light, --mitsuba, --define, --mitsuba-path
  docs/scale-out.md   --executor ray, --ray-address, --ray-cpus-per-task
  docs/sandbox.md     the bounds on sizes, spp and counts ("Bounds and outputs")
"""


def _int_list(text: str) -> tuple[int, ...]:
    try:
        values = tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise UserInputError(f"--spp expects comma-separated integers like 1,4,16 (got {text!r})") from None
    if not values:
        raise UserInputError(f"--spp expects comma-separated integers like 1,4,16 (got {text!r})")
    return values


def _families(text: str | None, have_usd: bool) -> tuple[str, ...]:
    if text is None:
        return () if have_usd else tuple(f.name for f in list_families())
    if text.strip() == "all":
        return tuple(f.name for f in list_families())
    names = tuple(dict.fromkeys(part.strip() for part in text.split(",") if part.strip()))
    return names


def _defaults() -> tuple[float, int]:
    return DEFAULT_REF_ERROR, DEFAULT_REF_SPP


def add_arguments(parser) -> None:
    parser.add_argument("--out", required=True, help="dataset folder (created; resumed when it exists)")
    parser.add_argument(
        "--families", default=None, help="comma-separated scene families, or 'all' (default: all, or none with --usd)"
    )
    parser.add_argument(
        "--scenes", type=int, default=1, help="scenes per family, seeds --seed, --seed+1, ... (default 1)"
    )
    parser.add_argument(
        "--frames",
        type=int,
        default=None,
        help="frames per family scene (default 8); for a --usd stage with its own time codes, how many of them "
        "to render, evenly spaced (default: all), and for --auto-camera without them the orbit's length",
    )
    parser.add_argument(
        "--time-range",
        default=None,
        metavar="START:END",
        help="render only a --usd stage's time codes from START to END (inclusive; with --frames N: N of "
        "them evenly spaced); recorded in dataset.json",
    )
    parser.add_argument("--width", type=int, default=128, help="image width in pixels (default 128)")
    parser.add_argument("--height", type=int, default=128, help="image height in pixels (default 128)")
    parser.add_argument("--spp", default="1,4,16", help="noisy sample counts, comma-separated (default 1,4,16)")
    parser.add_argument(
        "--ref-spp",
        type=int,
        default=None,
        help="cap of reference samples per pixel (default %d); with --ref-error 0: exactly this many" % _defaults()[1],
    )
    parser.add_argument(
        "--ref-error",
        type=float,
        default=None,
        metavar="E",
        help="render references until their noise floor (a perfect denoiser's relMSE) is <= E "
        "(default %g); 0: no adaptation; docs/references.md" % _defaults()[0],
    )
    parser.add_argument(
        "--max-depth",
        type=int,
        default=None,
        metavar="N",
        help="restrict path depth (Mitsuba's convention: 2 = direct light only; -1 = unbounded); "
        "default: full transport, or the stage's own denoisebench maxDepth",
    )
    parser.add_argument("--samples", action="store_true", help="also write per-sample data (large)")
    parser.add_argument(
        "--independent-rungs",
        action="store_true",
        help="render every --spp on its own (uncorrelated inputs; costs the sum of the rungs) instead of "
        "nested rungs: prefixes of one progressive render, which cost what the top rung costs",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="dataset seed: scene seeds, render seeds, splits (default 0)"
    )
    parser.add_argument(
        "--usd",
        action="append",
        default=[],
        metavar="FILE",
        help="render your own USD stage too (repeatable; .usda/.usdc/.usd/.usdz)",
    )
    parser.add_argument(
        "--mitsuba",
        "--xml",
        dest="xml",
        action="append",
        default=[],
        metavar="FILE",
        help="render a Mitsuba 3 XML scene too, from its sensor held still over --frames (repeatable)",
    )
    parser.add_argument(
        "--define",
        "-D",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a $NAME parameter of the --mitsuba scenes (repeatable; Mitsuba's -D); $spp and the film "
        "size ($res, $resx, $resy) need none: denoisebench sets its own",
    )
    parser.add_argument(
        "--mitsuba-path",
        action="append",
        default=[],
        metavar="DIR",
        help="also find the --mitsuba scenes' files in DIR, after each scene's own folder (repeatable; "
        "Mitsuba's -a); the dataset's copies hold every file, so DIR is not recorded",
    )
    parser.add_argument(
        "--scene-list",
        default=None,
        metavar="FILE",
        help="render the scenes a scene list names (TOML; a shipped list by name, e.g. mitsuba_docs, "
        "usd_wg_assets), found under --root (default none); e.g. --scene-list mitsuba_docs --root ~/mitsuba-data",
    )
    parser.add_argument(
        "--root",
        default=None,
        metavar="DIR",
        help="the folder a --scene-list's paths are relative to: a clone of the repository the list names (default none)",
    )
    parser.add_argument(
        "--camera", default=None, metavar="PATH", help="camera prim of the --usd stages (default: the first)"
    )
    parser.add_argument(
        "--auto-camera",
        action="store_true",
        help="frame --usd stages and --mitsuba scenes with a slow orbiting camera over --frames frames "
        "(for scenes without a camera; replaces a --mitsuba scene's sensor)",
    )
    parser.add_argument(
        "--default-light",
        action="store_true",
        help="light --usd stages that have no light: a uniform dome plus a key distant light",
    )
    parser.add_argument(
        "--executor",
        choices=("local", "ray"),
        default="local",
        help="local: this process, all cores (default); ray: spread frames over a Ray cluster (docs/scale-out.md)",
    )
    parser.add_argument("--ray-address", default=None, help="Ray cluster address (default: start a local cluster)")
    parser.add_argument(
        "--ray-cpus-per-task", type=int, default=1, help="CPUs (and Dr.Jit threads) per Ray task (default 1)"
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="overwrite a dataset made with another config; or write the dataset into a non-empty folder that is no "
        "dataset, beside its files (refused where one of the dataset's names is taken)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _ref_error(value: float | None) -> float | None:
    if value is None:
        return _defaults()[0]
    if value != value or value < 0 or value == float("inf"):
        raise UserInputError(f"--ref-error must be a positive number, or 0 for a fixed --ref-spp (got {value})")
    return None if value == 0 else float(value)


def _scene_list(args) -> dict:
    """The --scene-list's --usd/--mitsuba scenes and their options, merged with the ones given (or {})."""
    if getattr(args, "scene_list", None) is None:
        if getattr(args, "root", None) is not None:
            raise UserInputError("--root is the folder a --scene-list's paths are relative to: give --scene-list too")
        return {}
    from denoisebench.generator.scene_lists import read_scene_list, request_fields

    if args.root is None:
        raise UserInputError(f"--scene-list {args.scene_list}: give --root, the clone its scenes lie in")
    fields = request_fields(read_scene_list(args.scene_list), args.root)
    given = dict(parse_defines(args.define))
    return {
        "usd": tuple(args.usd) + fields["usd"],
        "xml": tuple(args.xml) + fields["xml"],
        "camera": args.camera or fields["camera"],
        "auto_camera": args.auto_camera or fields["auto_camera"],
        "default_light": args.default_light or fields["default_light"],
        "defines": tuple(sorted({**dict(fields["defines"]), **given}.items())),
    }


def request_from_args(args):
    listed = _scene_list(args)
    return _request(args, listed)


def _request(args, listed: dict):
    usd = listed.get("usd", tuple(args.usd))
    xml = listed.get("xml", tuple(args.xml))
    return GenerateRequest(
        out=Path(args.out),
        families=_families(args.families, bool(usd or xml)),
        scenes=args.scenes,
        frames=8 if args.frames is None else args.frames,
        time_range=_time_range(args.time_range),
        stage_frames=args.frames if args.usd and args.frames is not None else None,
        width=args.width,
        height=args.height,
        spp=_int_list(args.spp),
        ref_spp=_defaults()[1] if args.ref_spp is None else args.ref_spp,
        ref_error=_ref_error(args.ref_error),
        max_depth=args.max_depth,
        samples=args.samples,
        seed=args.seed,
        usd=usd,
        xml=xml,
        camera=listed.get("camera", args.camera),
        auto_camera=listed.get("auto_camera", args.auto_camera),
        default_light=listed.get("default_light", args.default_light),
        independent_rungs=args.independent_rungs,
        defines=listed.get("defines", tuple(parse_defines(args.define).items())),
        search_paths=tuple(args.mitsuba_path),
        force=args.force,
    )


def _time_range(text: str | None) -> tuple[float, float] | None:
    """``"START:END"`` -> (start, end), start <= end; None for None."""
    if text is None:
        return None
    start, sep, end = text.partition(":")
    try:
        values = (float(start), float(end)) if sep else None
    except ValueError:
        values = None
    if values is None or not all(v == v and abs(v) != float("inf") for v in values) or values[0] > values[1]:
        raise UserInputError(f"--time-range wants START:END with START <= END, e.g. 0:120 (got {text!r})")
    return values


def _first_names(names: list, shown: int = 12) -> str:
    """The first ``shown`` names, comma-separated, and how many more."""
    more = f" and {len(names) - shown} more" if len(names) > shown else ""
    return ", ".join(names[:shown]) + more


def print_summary(summary) -> None:
    state = "complete" if summary.complete else "INCOMPLETE (rerun the command to finish it)"
    print(
        f"{summary.out}: {summary.scenes} scene(s), {summary.frames} frame(s) rendered"
        + (f", {summary.skipped} already done" if summary.skipped else "")
        + f"; {summary.files} EXR file(s) in {summary.render_seconds:.2f} s of rendering"
        f" ({summary.samples_per_second:.3g} samples/s), {summary.wall_seconds:.1f} s wall; dataset {state}"
    )
    if summary.too_noisy:
        print(
            f"warning: {summary.too_noisy} frame(s) have a reference not 4x less noisy than their inputs "
            f"(reference_too_noisy in dataset.json); raise --ref-spp",
            file=sys.stderr,
        )
    if summary.at_cap:
        print(
            f"warning: {len(summary.at_cap)} reference(s) stopped at the --ref-spp cap before reaching --ref-error: "
            f"{_first_names(summary.at_cap)} (reference_adaptive in dataset.json)",
            file=sys.stderr,
        )
    if summary.rising:
        print(
            f"warning: {len(summary.rising)} reference(s) have a noise-floor estimate still rising with spp "
            f"(fireflies not yet resolved; their floor is a lower bound): {_first_names(summary.rising)} "
            f"(floor_growth in dataset.json)",
            file=sys.stderr,
        )
    for failure in summary.failures:
        print(f"failed: scene {failure.scene} frame {failure.frame}: {failure.message}", file=sys.stderr)


def run(args) -> int:
    request = request_from_args(args)
    validate_request(request)  # before a Ray cluster is started for nothing

    check_writable_dir(request.out, "--out")  # one line and exit 2, not a traceback after set-up
    check_out_folder(request)  # someone's folder that is no dataset: refused unless --force
    if request.ref_spp < REFERENCE_SPP_FACTOR * max(request.spp):
        print(
            f"warning: --ref-spp {request.ref_spp} is below {REFERENCE_SPP_FACTOR}x the largest --spp "
            f"({max(request.spp)}): references will likely be flagged too noisy",
            file=sys.stderr,
        )

    # a lower bound of the dataset's size against the free space, before anything is rendered
    frames = (len(request.families) * request.scenes + len(request.usd) + len(request.xml)) * request.frames
    shape = {"width": request.width, "height": request.height, "frames": frames, "rungs": len(request.spp)}
    disk_space.check_generate(request.out, **shape)
    per_file = disk_space.generate_lower_bound(**{**shape, "frames": 1, "rungs": 0})
    remaining = lambda: disk_space.remaining_exr_bytes(request.out, frames * (len(request.spp) + 1), per_file)  # noqa: E731
    executor = make_executor(args.executor, args.ray_address, cpus_per_task=args.ray_cpus_per_task)
    try:
        with disk_space.full_disk_is_one_line(request.out, "--out", "the dataset", remaining):
            summary = generate_dataset(request, executor, progress=not args.quiet)
    finally:
        executor.close()
    print_summary(summary)
    return 1 if summary.failures else 0

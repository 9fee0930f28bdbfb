"""Scene families and stages: list the families, author one as USD, preview a stage.

list                      families with their effects
make FAMILY --seed N --out DIR
                          author DIR/scene.usda (+ DIR/textures/)
preview FILE.usda --out preview.png [--frame i]
                          a quick Mitsuba render of a stage, tone-mapped to PNG
check FILE.usda           translate a stage and print its effects, render plan and warnings

preview and check read a Mitsuba 3 XML scene (FILE.xml) too, as ``generate-dataset --mitsuba`` does:
its first sensor, or with --auto-camera the orbit USD stages get (--camera and --default-light are
for USD stages only).
"""

from __future__ import annotations

import argparse
import json
import sys

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.render_plan import make_render_plan
from denoisebench.generator.dataset_run import transport_note
from denoisebench.generator.dataset_scenes import stage_options
from denoisebench.generator.mitsuba_xml import load_mitsuba_xml
from denoisebench.generator.mitsuba_xml_structure import parse_defines
from denoisebench.generator.preview import render_preview, tone_map_preview, write_png
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.scenes import get_family, list_families
from denoisebench.scenes.effects import DECLARED_ONLY

EPILOG = """examples:
  denoisebench scenes list
  denoisebench scenes make glossy_fireflies --seed 7 --out scenes/fireflies_7 --frames 8
  denoisebench scenes preview scenes/fireflies_7/scene.usda --out fireflies.png --frame 3
  denoisebench scenes preview my_shot.usda --out direct_only.png --max-depth 2
  denoisebench scenes check my_shot.usda
  denoisebench scenes preview asset.usdz --auto-camera --default-light --out asset.png
  denoisebench scenes check shot.usda --camera /World/Cameras/Close
  denoisebench scenes check mitsuba-data/scenes/cbox/cbox.xml
  denoisebench scenes preview cbox.xml --auto-camera --out cbox_orbit.png --frame 4
  denoisebench scenes check mitsuba-data/tests/scenes/floating_sphere/test_directional_direct.xml -D integrator=path

documentation:
  docs/scenes.md      the families, the supported USD subset (--camera, --auto-camera, --default-light),
                      Mitsuba XML scenes (--define, --mitsuba-path), participating media
  docs/references.md  --max-depth: restricting light transport on purpose
"""


def _add_stage_options(parser) -> None:
    parser.add_argument(
        "--camera", default=None, metavar="PATH", help="camera prim to render (default: the first camera)"
    )
    parser.add_argument(
        "--auto-camera",
        action="store_true",
        help="frame the stage's bounds with a slow orbiting camera (for stages without a camera; "
        "replaces a Mitsuba XML scene's sensor)",
    )
    parser.add_argument(
        "--default-light",
        action="store_true",
        help="light a stage that has no light: a uniform dome plus a key distant light",
    )
    parser.add_argument(
        "--define",
        "-D",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a $NAME parameter of a Mitsuba XML scene (repeatable; Mitsuba's -D); $spp and the film "
        "size ($res, $resx, $resy) need none: denoisebench sets its own",
    )
    parser.add_argument(
        "--mitsuba-path",
        action="append",
        default=[],
        metavar="DIR",
        help="also find a Mitsuba XML scene's files in DIR, after its own folder (repeatable; Mitsuba's -a)",
    )


def is_xml(path) -> bool:
    """A Mitsuba XML scene file (by its suffix), not a USD stage."""
    return str(path).lower().endswith(".xml")


def translate_options(args, frames: int = 8) -> dict:
    """Keywords of ``translate_usd`` from --camera/--auto-camera/--default-light (strict: refuse black stages);
    for a Mitsuba ``.xml`` file, those of ``load_mitsuba_xml`` (frames, --auto-camera, --define)."""
    if args.camera and args.auto_camera:
        raise UserInputError("give --camera or --auto-camera, not both")
    if is_xml(args.usd):
        for flag, given in (("--camera", args.camera), ("--default-light", args.default_light)):
            if given:
                raise UserInputError(
                    f"{flag} applies to USD stages; a Mitsuba XML scene uses its first sensor "
                    "or --auto-camera, and its own emitters"
                )
        return {
            "frames": frames,
            "auto_camera": bool(args.auto_camera),
            "defines": parse_defines(args.define),
            "search_paths": tuple(getattr(args, "mitsuba_path", ()) or ()),
        }
    if getattr(args, "define", None) or getattr(args, "mitsuba_path", None):
        raise UserInputError("--define and --mitsuba-path apply to Mitsuba XML scenes, not to USD stages")

    return {**stage_options(args.camera, args.auto_camera, args.default_light, frames), "strict": True}


def add_arguments(parser) -> None:
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True

    def action(name: str, help_text: str, description: str, examples: str):
        return actions.add_parser(
            name,
            help=help_text,
            description=description,
            epilog="examples:\n" + examples,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )

    action(
        "list",
        "families with their effects",
        "List the procedural scene families, each with the effects it exercises (what `make` and "
        "generate-dataset --families take).",
        "  denoisebench scenes list\n",
    )
    make = action(
        "make",
        "author one scene of a family as USD",
        "Author one scene of a family as a USD stage: DIR/scene.usda (+ DIR/textures/). The same family, "
        "seed and frames give byte-identical files.",
        "  denoisebench scenes make cornell --out scenes/cornell_0\n"
        "  denoisebench scenes make glossy_fireflies --seed 7 --frames 4 --out scenes/fireflies_7\n",
    )
    make.add_argument("family", help="family name (see `denoisebench scenes list`)")
    make.add_argument("--seed", type=int, default=0, help="random seed (default 0; same seed: byte-identical files)")
    make.add_argument("--frames", type=int, default=8, help="frames in the camera animation (default 8)")
    make.add_argument("--out", required=True, help="output folder: gets scene.usda and textures/")
    preview = action(
        "preview",
        "render a quick tone-mapped PNG of a stage",
        "Render one frame of a USD stage (or a Mitsuba 3 XML scene) with Mitsuba and write it tone-mapped "
        "as a PNG: a quick look, not a reference.",
        "  denoisebench scenes preview scenes/cornell_0/scene.usda --out cornell.png\n"
        "  denoisebench scenes preview scenes/cornell_0/scene.usda --out small.png --width 64 --height 64 "
        "--spp 16 --frame 2\n",
    )
    preview.add_argument("usd", help="a .usda/.usdc/.usd/.usdz file, or a Mitsuba 3 .xml scene")
    preview.add_argument("--out", required=True, help="PNG to write")
    preview.add_argument("--frame", type=int, default=0, help="frame index (default 0)")
    preview.add_argument("--width", type=int, default=256, help="image width in pixels (default 256)")
    preview.add_argument("--height", type=int, default=256, help="image height in pixels (default 256)")
    preview.add_argument("--spp", type=int, default=64, help="samples per pixel (default 64)")
    preview.add_argument(
        "--max-depth",
        type=int,
        default=None,
        metavar="N",
        help="restrict path depth (Mitsuba's convention: 2 = direct light only; -1 = unbounded); "
        "default: full transport, or the stage's own denoisebench maxDepth",
    )
    _add_stage_options(preview)
    check = action(
        "check",
        "translate a stage; print effects, render plan and warnings",
        "Translate a USD stage (or a Mitsuba 3 XML scene) as generate-dataset would, without rendering: print "
        "its effects, render plan and translation warnings. Defaults: the first camera, no added light.",
        "  denoisebench scenes check scenes/cornell_0/scene.usda\n"
        "  denoisebench scenes check scenes/cornell_0/scene.usda --auto-camera --default-light\n",
    )
    check.add_argument("usd", help="a .usda/.usdc/.usd/.usdz file, or a Mitsuba 3 .xml scene")
    _add_stage_options(check)


def run(args) -> int:
    return {"list": _list, "make": _make, "preview": _preview, "check": _check}[args.action](args)


def _family(name: str):
    try:
        return get_family(name)
    except (KeyError, ValueError) as error:
        raise UserInputError(str(error).strip("'\"")) from None


def _list(args) -> int:
    families = list_families()
    width = max(len(f.name) for f in families)
    for family in families:
        print(f"{family.name:<{width}}  {', '.join(family.effects)}")
        print(f"{'':<{width}}  {family.description}")
    return 0


def _make(args) -> int:
    if args.frames < 1:
        raise UserInputError(f"--frames must be at least 1 (got {args.frames})")
    family = _family(args.family)
    path = family.author(args.out, seed=args.seed, frames=args.frames)
    print(path)
    return 0


def _report_warnings(translated) -> None:
    for line in translated.warnings:
        print(f"warning: {line}", file=sys.stderr)
    mismatch = translated.effects_mismatch
    if mismatch:
        print(f"warning: effects declared and found differ: {json.dumps(mismatch, sort_keys=True)}", file=sys.stderr)


def _preview(args) -> int:
    if args.width < 1 or args.height < 1 or args.spp < 1:
        raise UserInputError("--width, --height and --spp must be positive")
    image, translated = render_preview(
        args.usd,
        frame=args.frame,
        width=args.width,
        height=args.height,
        spp=args.spp,
        max_depth=args.max_depth,
        translate_options=translate_options(args),
        before_render=_report_warnings,
    )
    print(write_png(tone_map_preview(image), args.out))
    return 0


#: What the translator looks for to infer each effect (scenes.effects' vocabulary), for ``scenes check``.
INFERRED_FROM = {
    "depth_of_field": "a camera with fStop > 0",
    "motion_blur": "an open shutter with an animated camera or prim",
    "glossy": "a rough specular lobe (0 < roughness < ~0.4 with metallic or specular)",
    "specular": "a delta lobe (roughness ~0: a mirror or smooth dielectric)",
    "transmission": "opacity < 1 (refraction through a dielectric)",
    "textures": "a UsdUVTexture input",
    "area_lights": "a Rect, Sphere or Disk light, or emissive geometry",
    "environment": "a Dome light",
    "media": "a participating medium",
}


def explain_effects(declared, inferred) -> dict[str, str]:
    """{effect: why it is declared but not inferred, or inferred but not declared}: every difference said."""
    declared, inferred = set(declared), set(inferred)
    out = {}
    for effect in sorted(declared - inferred):
        if effect in DECLARED_ONLY:
            out[effect] = (
                "declared only: no stage shows by itself whether multi-bounce light matters; it names a per-effect "
                "column and decides nothing else (every scene renders full transport)"
            )
        else:
            out[effect] = (
                f"declared, but the stage has no {INFERRED_FROM.get(effect, 'sign of it')}: the render plan honours "
                "it anyway (the plan uses declared and inferred effects together)"
            )
    if declared:
        for effect in sorted(inferred - declared):
            out[effect] = (
                f"found on the stage ({INFERRED_FROM.get(effect, 'a sign of it')}) though not declared: the plan honours it"
            )
    return out


def _check(args) -> int:
    if is_xml(args.usd):
        translated, _ = load_mitsuba_xml(args.usd, **translate_options(args))
    else:
        translated = translate_usd(args.usd, **translate_options(args))
    _report_warnings(translated)
    plan = make_render_plan(translated.effects, stage_max_depth=translated.max_depth)
    print(
        json.dumps(
            {
                "family": translated.family or None,
                "frames": translated.camera.frames,
                "camera": translated.camera.prim_path,
                "effects_declared": list(translated.effects_declared),
                "effects_inferred": list(translated.effects_inferred),
                "effects_explained": explain_effects(translated.effects_declared, translated.effects_inferred),
                "warnings": list(translated.warnings),
                "render_plan": plan.to_dict(),
                "transport": plan.transport_line() + transport_note(translated, plan),
                "translated": translated.summary(),
            },
            indent=2,
            sort_keys=True,
        )
    )
    return 0

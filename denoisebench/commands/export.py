"""Export a dataset into the layout another tool reads: OIDN's training toolkit or Noisebase's loaders.

--format oidn: OUT/<split>/<scene>_f0000_0004spp.{hdr,alb,nrm}.exr at every rung of the spp ladder,
OUT/<split>/<scene>_f0000_ref.hdr.exr (the reference, OIDN's target) and OUT/<split>/<scene>.json
({"exposure": x}); one single-layer float EXR (R,G,B) per feature, clipped as OIDN clips it on load.
Normals are world-space; albedo is the diffuse reflectance at the first non-delta hit. Images
smaller than --tile-size (OIDN's default 256) are refused: pass the same --tile_size to train.py
(and -l l1 below 161 px, where OIDN's default MS-SSIM loss cannot run).

--format noisebase: needs per-sample data (generate-dataset --samples). --layout train writes
OUT/<split>/seq0000.zip, one Zarr zip store per sequence for TrainingSampleLoader_v1; --layout test
writes OUT/<split>/<scene>/frame0000.zip per frame for TestSampleLoader_v1 (padded by the 28 rows
that loader crops). OUT/denoisebench_export.json holds the loader's `src` options for each split.

The export is written to a hidden folder beside OUT and renamed into place when complete: nothing
half-written is left behind. OUT must not exist (--force replaces it). Exit codes: 0 done, 2 bad
input (one line, nothing written), 1 internal failure.
"""

from __future__ import annotations

import sys
from pathlib import Path

from denoisebench.dataset.export import noisebase, oidn
from denoisebench.dataset.export.selection import select_scenes
from denoisebench.dataset.export.staging import check_target, staged_folder
from denoisebench.dataset.reader import open_dataset
from denoisebench.errors import UserInputError

# Lazy imports: zarr is optional (only --format noisebase needs it); it is imported there, with
# a one-line error when it is missing.

FORMATS = ("oidn", "noisebase")

EPILOG = """examples:
  denoisebench export data/small oidn_data --format oidn
  python training/preprocess.py hdr alb nrm -D oidn_data -t train -v val      # in OIDN's repository
  denoisebench export data/small oidn_data --format oidn --features hdr,alb,nrm,z --tile-size 64
  denoisebench export data/samples nb_data --format noisebase --spp 8
  denoisebench export data/samples nb_test --format noisebase --layout test --scenes cornell_000,dim_room_000

documentation:
  docs/datasets.md  "Exporting to other tools": OIDN's training toolkit and Noisebase, step by step
"""


def add_arguments(parser) -> None:
    parser.add_argument("data", help="dataset folder (with dataset.json)")
    parser.add_argument("out", help="export folder (created; must not exist unless --force)")
    parser.add_argument("--format", required=True, choices=FORMATS, help="target layout")
    parser.add_argument(
        "--features", default="hdr,alb,nrm", help="oidn: features to write, of hdr,alb,nrm,z (default hdr,alb,nrm)"
    )
    parser.add_argument(
        "--tile-size", type=int, default=256, help="oidn: smallest image side allowed (OIDN's --tile_size, 256)"
    )
    parser.add_argument("--spp", type=int, default=None, help="noisebase: rung whose samples to export (default top)")
    parser.add_argument(
        "--layout", default="train", choices=("train", "test"), help="noisebase: loader to write for (default train)"
    )
    parser.add_argument("--scenes", default=None, help="comma-separated scene names to export (default: all)")
    parser.add_argument("--force", action="store_true", help="replace OUT when it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args) -> int:

    if not (Path(args.data) / "dataset.json").is_file():
        raise UserInputError(f"{args.data}: not a dataset folder (no dataset.json)")
    dataset = select_scenes(open_dataset(args.data), args.scenes)
    target = check_target(args.out, args.force, dataset.root)
    if args.format == "oidn":
        features = oidn.parse_features(args.features)
        oidn.check_exportable(dataset, features, args.tile_size)
        with staged_folder(target) as staging:
            summary = oidn.export_oidn(dataset, staging, features, args.tile_size, progress=not args.quiet)
        files = sum(summary["files"].values())
        print(f"{target}: {files} EXR file(s) in {', '.join(sorted(summary['files']))} for OIDN's training toolkit")
    else:
        try:
            import zarr  # noqa: F401
        except ImportError:
            raise UserInputError("--format noisebase needs the zarr package (pip install zarr==2.18.7)") from None

        noisebase.plan_export(dataset, args.spp, args.layout)
        with staged_folder(target) as staging:
            summary = noisebase.export_noisebase(dataset, staging, args.spp, args.layout, progress=not args.quiet)
        for scene in summary["unchecked_object_motion"]:
            print(f"warning: {scene}: thin lens or motion blur: not checked for moving objects", file=sys.stderr)
        print(f"{target}: Noisebase {args.layout} layout for split(s) {', '.join(summary['src'])}")
    sys.stdout.flush()
    return 0

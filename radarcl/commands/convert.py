"""`radarcl convert`: a map copied between the .npz file and the map store."""

from radarcl.commands.options import add_salvage, say_lost
from radarcl.maps import disk

SUMMARY = "copy a map between the .npz file and the map store"
DESCRIPTION = ("Reads an .npz map or a map store (a directory: zarr v3, versioned, incremental saves) and writes "
               "the other: the target's name decides (.npz, or anything else for a store).")


def add_arguments(parser):
    parser.add_argument("source", help="a map (.npz) or map store")
    parser.add_argument("target", help="the map to write")
    parser.add_argument("--force", action="store_true", help="replace an existing target (a map radarcl wrote)")
    add_salvage(parser)


def run(args):
    target = disk.check_output(args.target, args.force, inputs=[args.source])
    spec, n, lost = disk.convert(args.source, target, salvage=args.salvage)
    say_lost(lost)
    print(f"wrote {target}: {n} bricks of a {' x '.join(map(str, spec.shape))} grid at {spec.voxel_m:g} m"
          + (f" ({sum(len(e['keys']) for e in lost)} lost bricks left out)" if lost else ""))
    return 0

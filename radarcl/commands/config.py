"""`radarcl config show|save`: the effective map configuration and where each value came from."""

from radarcl.commands.options import add_config, resolve_config
from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.io import files

SUMMARY = "show or save the effective map configuration"
DESCRIPTION = ("`config show` prints every configuration key with its value and where it came from (radarcl "
               "default, the sensor's geometry, its profile, the --config file, a flag), and how the windows in "
               "metres become bins. `config save FILE` writes it as a file for --config.")


def add_arguments(parser):
    parser.add_argument("action", choices=["show", "save"])
    parser.add_argument("file", nargs="?", help="config save: the file to write")
    parser.add_argument("--force", action="store_true", help="config save: replace an existing file")
    add_config(parser)


def run(args):
    if args.action == "save" and not args.file:
        raise ConfigError("config save needs the FILE to write")
    config = resolve_config(args)
    if args.action == "save":
        path = files.check(args.file, args.force, inputs=[args.config], what="configuration file")
        config.save(path, header=("radarcl map configuration", "written by radarcl config save"), overwrite=True)
        print(f"wrote {path}")
        return 0
    print("\n".join(mapconfig.show(config)))
    return 0

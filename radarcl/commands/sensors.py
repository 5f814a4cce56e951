"""`radarcl sensors`: the built-in sensor profiles, or one printed as TOML."""

from radarcl.config import sensors

SUMMARY = "list the built-in sensor profiles, or print one"
DESCRIPTION = ("Lists the built-in sensor profiles (radarcl/profiles/*.toml), or prints one as TOML: copy it to "
               "describe your own radar and pass the file to --sensor.")


def add_arguments(parser):
    parser.add_argument("name", nargs="?", help="a profile name or file to print")


def run(args):
    if args.name:
        print(sensors.load(args.name).toml(), end="")
        return 0
    for name in sensors.builtin_names():
        s = sensors.load(name)
        print(f"{name:20s} {s.input:8s} {s.description}")
    print("(radarcl sensors NAME prints a profile; --sensor takes a name or a TOML file)")
    return 0

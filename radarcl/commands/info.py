"""`radarcl info`: the OpenCL platforms and devices, and what the kernels need; `radarcl info BAG`:
a ROS 2 bag's topics."""

SUMMARY = ("list OpenCL platforms and devices, what the kernels need, and which devices pass radarcl's check; "
           "with BAG: a ROS 2 bag's topics")
DESCRIPTION = ("List OpenCL platforms and devices and what the kernels need. Each device is checked once (per driver "
               "version and radarcl version, the verdict cached in ~/.cache/radarcl/devices.json) in a child process: "
               "every kernel of every built-in pipeline built and run against the float64 oracle; a device that fails "
               "or crashes is marked UNUSABLE with the reason and never chosen. With BAG (a ROS 2 bag's folder, or "
               "its .db3 or .mcap file): its topics, their types and message counts, and which radarcl reads as "
               "radar scans or poses.")


def add_arguments(parser):
    parser.add_argument("bag", nargs="?", default=None, metavar="BAG", help="a ROS 2 bag to list instead")
    parser.add_argument("--msg-dir", default=None, metavar="FOLDER",
                        help="message definitions the bag does not carry, as FOLDER/<package>/msg/<Name>.msg")


def run(args):
    if args.bag is not None:
        from pathlib import Path

        from radarcl.errors import FrameFormatError
        from radarcl.io.rosbag import Bag

        if not Path(args.bag).exists():
            raise FrameFormatError(f"{args.bag} does not exist")
        with Bag(args.bag, args.msg_dir) as bag:
            print("\n".join(bag.listing()))
        return 0
    from radarcl.cl import choose_device, device_report

    print("\n".join(device_report()))
    choose_device()  # after the listing: no usable device, or a RADARCL_DEVICE that fits none, is an error
    return 0

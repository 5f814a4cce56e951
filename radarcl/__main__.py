"""`python -m radarcl`: the command line. Guarded, because fuse-many's Dask workers start by
spawning processes that import the main module."""

from radarcl.cli import main

if __name__ == "__main__":
    raise SystemExit(main())

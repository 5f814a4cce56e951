"""The radarcl volume viewer: the evidence grid ray-marched as a 3D texture with moderngl,
interactive (``radarcl view``) and headless through EGL (``radarcl render``).

It consumes numpy snapshots (``viewer.volume``: map files, dense arrays, brick updates) and
never imports pyopencl, so it runs where no OpenCL is installed, beside a fusion that writes
the map (``--live``).

- ``volume``    numpy: texture values, the coarse max-mip, downsampling to the GL limit
- ``camera``    the orbit camera and the projection that tests use to find a voxel's pixel
- ``modes``     the render modes, registered in one place, and the transfer function
- ``renderer``  moderngl: textures, programs from ``shaders/*.glsl``, drawing
- ``overlay``   colour bar, help and status text as textures (Pillow)
- ``headless``  ``radarcl render`` and the viewer bench's timing loop
- ``app``       ``radarcl view``: the window (moderngl-window), keys, live updates
"""

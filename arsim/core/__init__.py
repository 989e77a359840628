"""Conventions and plumbing every stage shares: directions and layouts, cameras, HDR files, GL context."""

from arsim.core.public import lazy_names

__all__, __getattr__ = lazy_names(__name__, {
    "errors": ("ArsimError",),
    "conventions": ("CameraIntrinsics",),
    "hdr_io": ("read_hdr", "write_image"),
    "resample": ("to_layout",),
    "gl": ("create_gl_context",),
    "png": ("read_frame",),
    "files": ("write_text_atomic",),
})

"""Conventions and plumbing every stage shares: directions and layouts, cameras, HDR files, GL context."""

_PUBLIC = {
    "ArsimError": "arsim.core.errors",
    "CameraIntrinsics": "arsim.core.conventions",
    "read_hdr": "arsim.core.hdr_io",
    "write_image": "arsim.core.hdr_io",
    "to_layout": "arsim.core.resample",
    "create_gl_context": "arsim.core.gl",
    "read_frame": "arsim.core.png",
    "write_text_atomic": "arsim.core.files",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    """The public names, imported when first used (importing the package stays cheap)."""
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

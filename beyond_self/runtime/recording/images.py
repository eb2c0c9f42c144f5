"""Camera frames on the bus <-> numpy images, in one place for every producer and consumer.

Raw frames are foxglove.RawImage-like (`CameraFrame`); compressed ones foxglove.CompressedImage
(`CompressedCameraFrame`, PNG or JPEG through Pillow, which matplotlib already depends on).
Recordings shipped with the project use JPEG to stay small; the segmenter is robust to it.
"""

from __future__ import annotations

import io

import numpy as np

from beyond_self.core.errors import InputError
from beyond_self.schemas.base import Header
from beyond_self.schemas.messages import RAW_ENCODINGS, CameraFrame, CompressedCameraFrame, Time

CameraMessage = CameraFrame | CompressedCameraFrame
_COLOUR = ("rgb8", "bgr8", "rgba8", "bgra8", "mono8")


def image_from_message(msg: CameraMessage) -> np.ndarray:
    """A camera message as a uint8 (H, W, 3) RGB array."""
    if isinstance(msg, CompressedCameraFrame):
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(io.BytesIO(msg.data)) as img:
                img.load()
                # an RGB image as it is: its conversion to RGB is a copy (as costly as decoding)
                return np.asarray(img if img.mode == "RGB" else img.convert("RGB"))
        except (UnidentifiedImageError, OSError, ValueError) as exc:
            raise InputError(
                f"compressed camera frame ({msg.format}) does not decode: {exc}"
            ) from None
    if msg.encoding not in _COLOUR:
        raise InputError(
            f"camera encoding {msg.encoding} is not a colour image; valid: {', '.join(_COLOUR)}"
        )
    bpp = RAW_ENCODINGS[msg.encoding]
    rows = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)
    px = rows[:, : msg.width * bpp].reshape(msg.height, msg.width, bpp)
    if msg.encoding in ("bgr8", "bgra8"):
        px = px[:, :, [2, 1, 0]]
    elif msg.encoding == "rgba8":
        px = px[:, :, :3]
    elif msg.encoding == "mono8":
        px = np.repeat(px, 3, axis=2)
    return np.ascontiguousarray(px)


def message_from_image(
    header: Header, image: np.ndarray, fmt: str = "raw", quality: int = 90, frame_id: str = "camera"
) -> CameraMessage:
    """An RGB uint8 image as a camera message: fmt "raw" (rgb8), "png" or "jpeg"."""
    img = np.ascontiguousarray(image, dtype=np.uint8)
    if img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"image has shape {img.shape}; valid: (height, width, 3) RGB")
    h, w = img.shape[:2]
    if fmt == "raw":
        return CameraFrame.build(header, w, h, img.tobytes(), "rgb8", frame_id)
    if fmt not in ("png", "jpeg"):
        raise InputError(f"camera format {fmt!r} unknown; valid: raw, png, jpeg")
    from PIL import Image

    buf = io.BytesIO()
    pil = Image.fromarray(img, "RGB")
    if fmt == "jpeg":
        # Full-resolution colour (4:4:4): the usual 4:2:0 chroma subsampling smears the colour
        # edges of small objects enough that the segmenter reads about a quarter of small boxes
        # as circles; 4:4:4 at quality 80 is about as small as 4:2:0 at 85.
        pil.save(buf, format="JPEG", quality=quality, subsampling=0, optimize=False)
    else:
        pil.save(buf, format="PNG", optimize=False)
    return CompressedCameraFrame(
        header=header,
        timestamp=Time.from_ns(header.stamp),
        frame_id=frame_id,
        format=fmt,
        data=buf.getvalue(),
        width=w,
        height=h,
    )

"""Reading and writing camera frames as files: binary/ASCII PPM (and PGM) natively, PNG through
matplotlib.

Why our own PPM reader: the robot's camera dumps (YARP `dataDumper`) are PPM, the format is ten
lines of code, and a hand-rolled reader can say exactly what is wrong with a broken file instead of
failing deep inside an imaging library. Every frame leaving this module is a C-contiguous uint8
array of shape (height, width, 3), RGB.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from beyond_self.core.errors import InputError

SUFFIXES = (".ppm", ".pgm", ".pnm", ".png")


def _tokens(data: bytes, count: int) -> tuple[list[bytes], int]:
    """The first `count` whitespace-separated header tokens (skipping # comments) and the offset
    just past the single whitespace byte that ends the last one."""
    tokens: list[bytes] = []
    i, n = 0, len(data)
    while len(tokens) < count:
        while i < n and data[i : i + 1].isspace():
            i += 1
        if i < n and data[i : i + 1] == b"#":
            while i < n and data[i : i + 1] not in (b"\n", b"\r"):
                i += 1
            continue
        start = i
        while i < n and not data[i : i + 1].isspace() and data[i : i + 1] != b"#":
            i += 1
        if start == i:
            break
        tokens.append(data[start:i])
    return tokens, i + 1


def decode_pnm(data: bytes, name: str = "image") -> np.ndarray:
    """Decode PPM/PGM bytes (P2, P3, P5, P6; maxval up to 65535) into uint8 RGB."""
    magic = data[:2]
    if magic not in (b"P2", b"P3", b"P5", b"P6"):
        raise InputError(f"{name} is not a PPM/PGM file (magic {magic!r}; valid: P2, P3, P5, P6)")
    tokens, offset = _tokens(data, 4)
    if len(tokens) < 4:
        raise InputError(f"{name} has a truncated PPM header")
    try:
        width, height, maxval = (int(t) for t in tokens[1:4])
    except ValueError:
        raise InputError(f"{name} has a malformed PPM header {b' '.join(tokens)!r}") from None
    if width <= 0 or height <= 0 or not 0 < maxval < 65536:
        raise InputError(f"{name} has an invalid PPM size {width}x{height} or maxval {maxval}")
    channels = 3 if magic in (b"P3", b"P6") else 1
    count = width * height * channels
    if magic in (b"P5", b"P6"):
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype(np.uint8)
        need = count * dtype.itemsize
        if len(data) - offset < need:
            raise InputError(
                f"{name} is truncated: {len(data) - offset} pixel bytes, expected {need} "
                f"for {width}x{height}"
            )
        pixels = np.frombuffer(data, dtype=dtype, count=count, offset=offset).astype(np.uint32)
    else:
        try:
            pixels = np.array(data[offset - 1 :].split()[:count], dtype=np.uint32)
        except ValueError:
            raise InputError(f"{name} has non-numeric ASCII pixel values") from None
        if pixels.size < count:
            raise InputError(f"{name} is truncated: {pixels.size} ASCII values, expected {count}")
    if maxval != 255:
        pixels = (pixels * 255 + maxval // 2) // maxval
    image = pixels.astype(np.uint8).reshape(height, width, channels)
    if channels == 1:
        image = np.repeat(image, 3, axis=2)
    return np.ascontiguousarray(image)


def encode_ppm(image: np.ndarray) -> bytes:
    """Binary PPM (P6) bytes of an RGB uint8 frame."""
    frame = as_frame(image)
    height, width = frame.shape[:2]
    return f"P6\n{width} {height}\n255\n".encode("ascii") + frame.tobytes()


def as_frame(image: np.ndarray, name: str = "frame") -> np.ndarray:
    """Check and normalise an in-memory image to uint8 (H, W, 3); grey and RGBA are converted.

    Float images are taken to be in [0, 1] (matplotlib's convention)."""
    arr = np.asarray(image)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim != 3 or arr.shape[2] not in (1, 3, 4):
        raise InputError(
            f"{name} has shape {arr.shape}; valid: (height, width) grey or (height, width, 3|4)"
        )
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise InputError(f"{name} is empty ({arr.shape[1]}x{arr.shape[0]} pixels)")
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{name} has NaN or infinite pixel values")
        arr = np.clip(np.rint(arr * 255.0), 0, 255).astype(np.uint8)
    elif arr.dtype == np.uint16:
        arr = ((arr.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
    elif arr.dtype != np.uint8:
        if arr.dtype.kind not in "iub" or arr.min() < 0 or arr.max() > 255:
            raise InputError(f"{name} has dtype {arr.dtype} outside 0..255; valid: uint8 RGB")
        arr = arr.astype(np.uint8)
    if arr.shape[2] == 1:
        arr = np.repeat(arr, 3, axis=2)
    elif arr.shape[2] == 4:
        arr = arr[:, :, :3]
    return np.ascontiguousarray(arr)


def read_image(path: str | Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """Read a PPM/PGM/PNG file as uint8 RGB (H, W, 3); `size` = (width, height) it must have."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"image {p} does not exist or is not a file")
    suffix = p.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(f"image {p} has suffix {suffix!r}; valid: {', '.join(SUFFIXES)}")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise InputError(f"image {p} cannot be read: {exc.strerror}") from None
    if not data:
        raise InputError(f"image {p} is an empty file")
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        image = _decode_png(p)
    elif data[:1] == b"P":
        image = decode_pnm(data, name=f"image {p}")
    else:
        raise InputError(f"image {p} is neither PPM/PGM nor PNG (first bytes {data[:4]!r})")
    if size is not None and (image.shape[1], image.shape[0]) != tuple(size):
        raise InputError(
            f"image {p} is {image.shape[1]}x{image.shape[0]}; expected {size[0]}x{size[1]}"
        )
    return image


def _decode_png(path: Path) -> np.ndarray:
    import matplotlib.image as mpimg

    try:
        arr = mpimg.imread(path, format="png")
    except (OSError, ValueError, SyntaxError) as exc:
        raise InputError(f"image {path} is not a readable PNG: {exc}") from None
    return as_frame(arr, name=f"image {path}")


def write_image(path: str | Path, image: np.ndarray) -> Path:
    """Write a frame as PPM (.ppm) or PNG (.png), creating the folder."""
    p = Path(path)
    frame = as_frame(image)
    suffix = p.suffix.lower()
    if suffix not in (".ppm", ".png"):
        raise InputError(f"cannot write {p}: suffix {suffix!r}; valid: .ppm, .png")
    p.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".ppm":
        p.write_bytes(encode_ppm(frame))
    else:
        import matplotlib.image as mpimg

        mpimg.imsave(p, frame, format="png")
    return p

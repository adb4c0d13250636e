"""Procedural texture images (uint8 RGB arrays) for the realistic visual domain.

Object designs are panoramas of shape (S, 4S, 3): rows run from the object's top to its bottom and
columns once around it (faces +x, +y, -x, -y, each seen from outside with its left edge first).
`cube_texture` turns a panorama and a lid colour into MuJoCo's stacked cube-texture layout.
"""

import numpy as np

OBJECT_PATTERNS = ("plain", "bands", "label", "stripes", "gradient", "print")
# rot90 turns that put a design's "up" on the object's +z in MuJoCo's cube faces 0-3 (+x, -x, +y, -y)
_FACE_TURNS = {0: 1, 1: 3, 2: 2, 3: 0}
# panorama quarter (around the object) -> cube face
_PANORAMA_FACES = (0, 2, 1, 3)


def random_colour(rng: np.random.Generator, dark: bool = False, muted: bool = False) -> np.ndarray:
    """A random saturated or neutral colour, float RGB in [0, 1]; dark: albedo below 0.1; muted:
    low saturation, as floors, walls and furniture mostly are."""
    hue = rng.uniform(0, 1)
    saturation = rng.uniform(0.0, 0.35) if muted else rng.choice([0.0, rng.uniform(0.4, 1.0)], p=[0.2, 0.8])
    value = rng.uniform(0.03, 0.09) if dark else rng.uniform(0.35, 1.0)
    k = (np.array([5.0, 3.0, 1.0]) + hue * 6.0) % 6.0
    return value - value * saturation * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)


def _glyph_rows(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    """Mask (height, width) of text-like marks: rows of short dark rectangles with gaps."""
    mask = np.zeros((height, width), bool)
    line_h = max(2, height // int(rng.integers(3, 7)))
    glyph_w = max(1, line_h // 2)
    for top in range(1, height - line_h, line_h + max(1, line_h // 2)):
        n = width // (glyph_w + 1)
        keep = rng.uniform(size=n) < 0.7
        starts = np.arange(n)[keep] * (glyph_w + 1)
        cols = (starts[:, None] + np.arange(glyph_w)[None]).ravel()
        mask[top : top + line_h, cols[cols < width]] = True
    return mask


def object_panorama(rng: np.random.Generator, size_px: int, pattern: str, dark: bool) -> np.ndarray:
    """One object's design (size_px, 4 size_px, 3) float in [0, 1]."""
    h, w = size_px, 4 * size_px
    base = random_colour(rng, dark)
    image = np.broadcast_to(base, (h, w, 3)).copy()
    rows = np.arange(h)[:, None]
    if pattern == "bands":
        cuts = np.sort(rng.integers(1, h, size=int(rng.integers(1, 4))))
        for cut in cuts:
            image[cut:] = random_colour(rng, dark)
    elif pattern == "label":
        top, bottom = sorted(rng.integers(h // 6, 5 * h // 6, size=2))
        bottom = min(h, max(bottom, top + h // 4))
        label = random_colour(rng) if not dark else random_colour(rng, dark=False) * 0.8
        image[top:bottom] = label
        ink = random_colour(rng, dark=True) if label.mean() > 0.4 else np.ones(3) * 0.95
        text = _glyph_rows(rng, bottom - top, w)
        image[top:bottom][text] = ink
        # a logo: a filled ellipse of high contrast in the label
        cy, cx = (top + bottom) / 2, rng.uniform(0, w)
        ry, rx = (bottom - top) * rng.uniform(0.25, 0.45), h * rng.uniform(0.2, 0.5)
        yy, xx = np.mgrid[0:h, 0:w]
        logo = ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 < 1.0
        image[logo] = 1.0 - label
    elif pattern == "stripes":
        period = int(rng.integers(4, max(5, h // 3)))
        slope = rng.choice([0.0, 0.5, 1.0, -1.0])
        cols = np.arange(w)[None, :]
        stripe = ((rows + slope * cols) // period) % 2 == 1
        image[stripe] = random_colour(rng, dark)
    elif pattern == "gradient":
        t = np.linspace(0, 1, h)[:, None, None]
        image = (1 - t) * base + t * random_colour(rng, dark)
        image = np.broadcast_to(image, (h, w, 3)).copy()
    elif pattern == "print":  # multi-coloured blocks and text, as a cereal box or a drill
        for _ in range(int(rng.integers(3, 8))):
            y0, x0 = int(rng.integers(0, h)), int(rng.integers(0, w))
            y1, x1 = y0 + int(rng.integers(h // 6, h // 2 + 1)), x0 + int(rng.integers(h // 4, h + 1))
            image[y0:y1, x0:x1] = random_colour(rng, dark)
        text = _glyph_rows(rng, h, w) & (rng.uniform(size=(1, w)) < 0.6)
        image[text] = random_colour(rng, dark=True) if not dark else np.ones(3) * 0.9
    grain = rng.normal(0.0, 0.015, size=(h, w, 1))
    return np.clip(image + grain, 0.0, 1.0)


def cube_texture(panorama: np.ndarray, lid_rgb: np.ndarray) -> np.ndarray:
    """MuJoCo cube-texture data (6 S, S, 3) uint8 from a panorama (S, 4 S, 3) and a lid colour."""
    s = panorama.shape[0]
    faces = [None] * 6
    for quarter, face in enumerate(_PANORAMA_FACES):
        design = panorama[:, quarter * s : (quarter + 1) * s]
        faces[face] = np.rot90(design, _FACE_TURNS[face])
    faces[4] = np.broadcast_to(lid_rgb, (s, s, 3))
    faces[5] = np.broadcast_to(lid_rgb * 0.6, (s, s, 3))
    return (np.concatenate(faces, 0) * 255).round().astype(np.uint8)


def _smooth_noise(rng: np.random.Generator, n: int, cells: int) -> np.ndarray:
    """1D noise of n samples, smooth over n / cells, in about [-1, 1]."""
    knots = rng.uniform(-1, 1, size=cells + 2)
    return np.interp(np.linspace(0, cells, n), np.arange(cells + 2), knots)


def wood(rng: np.random.Generator, size_px: int) -> np.ndarray:
    """Wood grain: long, slowly wandering stripes along the board, fine fibres, a light to dark brown."""
    x = np.arange(size_px)[None, :] / size_px
    wander = 0.04 * _smooth_noise(rng, size_px, 4)[:, None]  # stripes run along rows (y)
    frequency = rng.uniform(12, 30)
    rings = (np.sin(2 * np.pi * (x + wander) * frequency + 3 * _smooth_noise(rng, size_px, 8)[None, :]) + 1) / 2
    fibres = rng.normal(0, 0.04, size=(size_px, size_px)) + rng.normal(0, 0.05, size=(1, size_px))
    light = np.array([0.72, 0.52, 0.33]) * rng.uniform(0.4, 1.2)
    dark = light * rng.uniform(0.7, 0.88)
    t = np.clip(rings**3 + fibres, 0, 1)[..., None]
    return np.clip((1 - t) * light + t * dark, 0, 1)


def laminate(rng: np.random.Generator, size_px: int) -> np.ndarray:
    """Plain laminate: one pale or dark colour with fine speckle."""
    base = random_colour(rng, muted=True) * rng.uniform(0.3, 0.9) + rng.uniform(0.0, 0.3)
    return np.clip(base + rng.normal(0, 0.02, size=(size_px, size_px, 1)), 0, 1)


def tiles(rng: np.random.Generator, size_px: int) -> np.ndarray:
    """Square tiles with grout lines, alternating two close colours."""
    n = int(rng.integers(2, 6))
    y, x = np.mgrid[0:size_px, 0:size_px] * n // size_px
    a, b = random_colour(rng, muted=True), random_colour(rng, muted=True)
    image = np.where(((x + y) % 2 == 0)[..., None], a, 0.7 * a + 0.3 * b)
    cell = size_px // n
    grout = np.arange(size_px) % cell < max(1, cell // 16)
    image[grout] = 0.8
    image[:, grout] = 0.8
    return np.clip(image + rng.normal(0, 0.02, size=(size_px, size_px, 1)), 0, 1)


def carpet(rng: np.random.Generator, size_px: int) -> np.ndarray:
    """Carpet: a colour with strong per-pixel fibre noise."""
    base = random_colour(rng, muted=True) * rng.uniform(0.3, 0.8)
    return np.clip(base * (1 + rng.normal(0, 0.25, size=(size_px, size_px, 1))), 0, 1)


TABLE_TEXTURES = {"wood": wood, "laminate": laminate, "tiles": tiles}
FLOOR_TEXTURES = {"carpet": carpet, "tiles": tiles, "wood": wood}


def to_uint8(image: np.ndarray) -> np.ndarray:
    return (np.clip(image, 0, 1) * 255).round().astype(np.uint8)

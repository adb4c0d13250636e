"""The realistic visual domain: what a scene looks like beyond its geometry.

A SceneAppearance is drawn per scene (object textures, table and floor, table legs, furniture,
lights, the depth camera's misregistration) and a CameraResponse per frame (exposure, white
balance, gamma, sensor noise). Neither touches physics: furniture and legs do not collide, and a
Scene without an appearance renders in the plain domain (one flat colour per object, plain table).
"""

from dataclasses import dataclass, field

import numpy as np

from arm_sim import textures

DOMAINS = ("realistic", "plain")
DEFAULT_DOMAIN = "realistic"
OBJECT_TEXTURE_PX = 48
SURFACE_TEXTURE_PX = 256
TABLE_THICKNESS_M = 0.05  # as the plain table


@dataclass
class ObjectLook:
    texture: np.ndarray  # (6 S, S, 3) uint8 MuJoCo cube texture
    pattern: str
    dark: bool  # albedo below 0.1: the depth sensor loses much of it
    shiny: bool  # specular: highlights and missing returns


@dataclass
class StaticBox:
    """A box of the surroundings (leg, chair part, second table, floor box): no collisions."""

    name: str
    centre_m: tuple
    half_size_m: tuple
    rgb: tuple
    texture: str | None = None  # a name in SceneAppearance.surfaces


@dataclass
class Light:
    pos_m: tuple
    direction: tuple
    diffuse: tuple
    specular: tuple
    cast_shadow: bool


@dataclass
class SceneAppearance:
    objects: list[ObjectLook]
    surfaces: dict[str, np.ndarray]  # name -> (S, S, 3) uint8 2D texture ("table", "floor", ...)
    table_texture_repeat: tuple
    boxes: list[StaticBox] = field(default_factory=list)
    lights: list[Light] = field(default_factory=list)
    ambient: tuple = (0.3, 0.3, 0.3)
    depth_shift_px: tuple = (0, 0)  # depth-to-colour misregistration (columns, rows)
    shadows: bool = True  # the first light casts shadows (doubles the colour render's cost)

    def subset(self, keep: np.ndarray) -> "SceneAppearance":
        looks = [look for look, k in zip(self.objects, keep, strict=True) if k]
        return SceneAppearance(
            looks,
            self.surfaces,
            self.table_texture_repeat,
            self.boxes,
            self.lights,
            self.ambient,
            self.depth_shift_px,
            self.shadows,
        )


@dataclass
class CameraResponse:
    """Per-frame photometry of the colour camera."""

    exposure: float
    white_balance: tuple
    gamma: float
    read_noise: float  # std of additive noise, in [0, 1] intensity
    shot_noise: float  # std of signal-dependent noise at full intensity


def sample_object_look(rng: np.random.Generator) -> ObjectLook:
    pattern = str(rng.choice(textures.OBJECT_PATTERNS, p=[0.15, 0.2, 0.25, 0.1, 0.1, 0.2]))
    dark = bool(rng.uniform() < 0.12)
    shiny = bool(rng.uniform() < 0.2)
    panorama = textures.object_panorama(rng, OBJECT_TEXTURE_PX, pattern, dark)
    lid = panorama[0].mean(0) if rng.uniform() < 0.6 else textures.random_colour(rng, dark)
    return ObjectLook(textures.cube_texture(panorama, lid), pattern, dark, shiny)


def _table_legs(table_z: float, floor_z: float, half_extent: tuple, inset_m: float, rgb: tuple) -> list[StaticBox]:
    hx, hy = half_extent
    half_height = 0.5 * (table_z - TABLE_THICKNESS_M - floor_z)
    return [
        StaticBox(
            f"table_leg_{i}",
            (sx * (hx - inset_m), sy * (hy - inset_m), floor_z + half_height),
            (0.025, 0.025, half_height),
            rgb,
        )
        for i, (sx, sy) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1)))
    ]


def _chair(name: str, x: float, y: float, yaw: float, floor_z: float, rgb: tuple) -> list[StaticBox]:
    """Seat, back and four legs; axis-aligned parts placed around (x, y), back away from the table."""
    seat_h, half = 0.45, 0.21
    back_dir = np.array([np.cos(yaw), np.sin(yaw)])
    parts = [StaticBox(f"{name}_seat", (x, y, floor_z + seat_h), (half, half, 0.02), rgb)]
    bx, by = np.array([x, y]) + back_dir * half
    thin = (0.02, half) if abs(back_dir[0]) > abs(back_dir[1]) else (half, 0.02)
    parts.append(StaticBox(f"{name}_back", (bx, by, floor_z + seat_h + 0.22), (*thin, 0.22), rgb))
    for i, (sx, sy) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
        parts.append(
            StaticBox(
                f"{name}_leg_{i}",
                (x + sx * (half - 0.02), y + sy * (half - 0.02), floor_z + seat_h / 2),
                (0.015, 0.015, seat_h / 2),
                rgb,
            )
        )
    return parts


def _around_table(rng: np.random.Generator, half_extent: tuple, gap_m: float) -> tuple[float, float, float]:
    """A point beside the table (not on the robot's side, x < -0.4), and the yaw facing away from it."""
    hx, hy = half_extent
    while True:
        angle = rng.uniform(-0.75 * np.pi, 0.75 * np.pi)
        direction = np.array([np.cos(angle), np.sin(angle)])
        # distance to the table's edge along direction, then the gap
        reach = min(hx / max(abs(direction[0]), 1e-6), hy / max(abs(direction[1]), 1e-6)) + gap_m
        x, y = direction * reach
        if x > -0.4:
            return float(x), float(y), float(angle)


def sample_appearance(
    rng: np.random.Generator, n_objects: int, table_z: float, half_extent: tuple, floor_z: float
) -> SceneAppearance:
    """A random realistic look for a scene of n_objects on a table top at table_z (metres)."""
    looks = [sample_object_look(rng) for _ in range(n_objects)]
    table_kind = str(rng.choice(list(textures.TABLE_TEXTURES), p=[0.5, 0.35, 0.15]))
    floor_kind = str(rng.choice(list(textures.FLOOR_TEXTURES)))
    surfaces = {
        "table": textures.to_uint8(textures.TABLE_TEXTURES[table_kind](rng, SURFACE_TEXTURE_PX)),
        "floor": textures.to_uint8(textures.FLOOR_TEXTURES[floor_kind](rng, SURFACE_TEXTURE_PX)),
        "furniture": textures.to_uint8(textures.wood(rng, SURFACE_TEXTURE_PX)),
        "wall": textures.to_uint8(textures.laminate(rng, 64)),
    }
    leg_rgb = tuple(textures.random_colour(rng) * 0.6)
    boxes = _table_legs(table_z, floor_z, half_extent, float(rng.uniform(0.03, 0.12)), leg_rgb)
    for i in range(int(rng.integers(0, 3))):
        x, y, yaw = _around_table(rng, half_extent, float(rng.uniform(0.15, 0.5)))
        boxes += _chair(f"chair_{i}", x, y, yaw, floor_z, tuple(textures.random_colour(rng, muted=True) * 0.8))
    if rng.uniform() < 0.5:  # a second table at another height
        x, y, _ = _around_table(rng, half_extent, float(rng.uniform(0.5, 0.9)))
        top_z = floor_z + float(rng.uniform(0.4, 0.95))
        half = (float(rng.uniform(0.25, 0.45)), float(rng.uniform(0.25, 0.45)))
        boxes.append(StaticBox("side_table", (x, y, top_z - 0.02), (*half, 0.02), (0.5, 0.4, 0.3), "furniture"))
        boxes += [
            StaticBox(
                f"side_table_leg_{k}",
                (x + sx * (half[0] - 0.03), y + sy * (half[1] - 0.03), (floor_z + top_z) / 2),
                (0.02, 0.02, (top_z - floor_z) / 2),
                (0.3, 0.3, 0.3),
            )
            for k, (sx, sy) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1)))
        ]
    for i in range(int(rng.integers(0, 4))):  # boxes on the floor
        x, y, _ = _around_table(rng, half_extent, float(rng.uniform(0.1, 0.6)))
        half = tuple(float(v) for v in rng.uniform(0.08, 0.25, size=3))
        rgb = tuple(textures.random_colour(rng, muted=True))
        boxes.append(StaticBox(f"floor_box_{i}", (x, y, floor_z + half[2]), half, rgb))
    lights = []
    for i in range(int(rng.integers(1, 4))):
        azimuth, elevation = rng.uniform(0, 2 * np.pi), rng.uniform(np.deg2rad(35), np.deg2rad(85))
        distance = rng.uniform(1.5, 3.0)
        pos = distance * np.array(
            [np.cos(azimuth) * np.cos(elevation), np.sin(azimuth) * np.cos(elevation), np.sin(elevation)]
        )
        warmth = rng.uniform(-0.15, 0.15)
        colour = np.clip(np.array([1 + warmth, 1.0, 1 - warmth]) * rng.uniform(0.35, 0.8), 0, 1)
        lights.append(
            Light(
                tuple(pos + (0, 0, table_z)),
                tuple(-pos / distance),
                tuple(colour),
                tuple(colour * rng.uniform(0.2, 0.6)),
                cast_shadow=i == 0,
            )
        )
    shift = tuple(int(v) for v in rng.integers(-1, 2, size=2))
    ambient = tuple(np.full(3, rng.uniform(0.25, 0.45)))
    repeat = (1.0, 1.0)  # the procedural surfaces do not tile seamlessly
    shadows = bool(rng.uniform() < 0.5)
    walls = ((3.0, 0.0, 0.05, 3.0), (-3.0, 0.0, 0.05, 3.0), (0.0, 3.0, 3.0, 0.05), (0.0, -3.0, 3.0, 0.05))
    for i, (x, y, hx, hy) in enumerate(walls):
        boxes.append(StaticBox(f"wall_{i}", (x, y, floor_z + 1.5), (hx, hy, 1.5), (1.0, 1.0, 1.0), "wall"))
    return SceneAppearance(looks, surfaces, repeat, boxes, lights, ambient, shift, shadows)


def sample_camera_response(rng: np.random.Generator) -> CameraResponse:
    return CameraResponse(
        exposure=float(np.exp(rng.normal(0.0, 0.25))),
        white_balance=tuple(float(v) for v in np.exp(rng.normal(0.0, 0.06, size=3))),
        gamma=float(rng.uniform(0.8, 1.25)),
        read_noise=float(rng.uniform(0.004, 0.015)),
        shot_noise=float(rng.uniform(0.01, 0.04)),
    )


def apply_camera_response(rgb: np.ndarray, response: CameraResponse, rng: np.random.Generator) -> np.ndarray:
    """Exposure, white balance, gamma and sensor noise on a rendered uint8 RGB image."""
    linear = rgb.astype(np.float32) / 255.0
    linear *= np.float32(response.exposure) * np.asarray(response.white_balance, np.float32)
    linear = np.clip(linear, 0.0, 1.0) ** np.float32(response.gamma)
    sigma = np.sqrt(response.read_noise**2 + (response.shot_noise**2) * linear)
    noisy = linear + sigma * rng.standard_normal(linear.shape, dtype=np.float32)
    return (np.clip(noisy, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)

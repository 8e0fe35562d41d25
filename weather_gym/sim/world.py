"""The PyBullet world: textured ground and sky, knock-over-able cones, the car's body, the camera.

A ``World`` owns one PyBullet physics client (DIRECT by default) and disconnects it in ``close()``
(or, deferred, when it is garbage collected). Every method first makes the world's EGL context
current (:func:`weather_gym.sim.renderer.activate`), so any number of worlds in a process render
what each would render alone, in any order of creation and closing. With
``SimConfig(renderer="none")`` nothing is rendered for the camera; :meth:`World.ground_truth` then
gives the visible cones from geometry.

Example:
    >>> from weather_gym.tracks import load_track
    >>> from weather_gym.sim.world import World
    >>> world = World(load_track("small_track"))           # doctest: +SKIP
    >>> frame = world.render()                              # doctest: +SKIP
    >>> frame.rgb.shape                                     # doctest: +SKIP
    (376, 672, 3)
    >>> world.close()                                       # doctest: +SKIP

Without a renderer (physics and geometric ground truth only) a world is cheap:
    >>> from weather_gym.sim.config import SimConfig
    >>> world = World(load_track("small_track"), sim=SimConfig(renderer="none"))
    >>> world.renderer_name, world.cone_xy.shape
    ('none', (..., 2))
    >>> world.close()
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_spec import CONE_BASE_M, CONE_CLASSES, CONE_HEIGHT_M
from weather_gym.core.errors import StateError
from weather_gym.sim import renderer as _renderer
from weather_gym.sim import scenery
from weather_gym.sim.bullet import pybullet as p
from weather_gym.sim.camera_sensor import CameraSensor
from weather_gym.sim.car import Car
from weather_gym.sim.cast_shadows import ShadowCaster
from weather_gym.sim.config import CarConfig, SimConfig
from weather_gym.sim.egl.shadow_reuse import ShadowMapReuse
from weather_gym.sim.lidar import LidarSensor
from weather_gym.sim.lidar_config import LidarConfig
from weather_gym.sim.look import DEFAULT_LOOK, REALISTIC_LOOK, Look
from weather_gym.sim.mesh_files import mesh_file
from weather_gym.sim.meshes import box_obj, cone_dimensions, cone_obj
from weather_gym.sim.renderer import renderer_flag
from weather_gym.sim.scene_files import clutter_file, ground_file, realistic_ground_files
from weather_gym.sim.scenery_textures import add_skyline, realistic_cone_texture
from weather_gym.sim.textures import cone_texture, sky_panorama
from weather_gym.sim.world_views import WorldViews

CAR_BODY_HEIGHT_M = 0.35  # the car's body box (collision and chase-view visual)
SHADOW_DISC_SCALE = 0.75  # a cone's contact shadow: a disc of this many base widths' radius
GROUND_MARGIN_M = 90.0  # ground beyond the track; more than the camera's far plane
CONE_REACH_M = 0.35
"""Margin (m) around the car's body within which cones get contact physics: a big cone's base
half-diagonal (0.2 m) plus safety (the motion during the control period is added to it)."""
RESTING_SPEED = 1e-3
"""A knocked cone slower than this (m/s and rad/s, each component) lies still."""


class World(WorldViews):
    """Scene + car + camera for one track. Not thread-safe; one per env."""

    def __init__(
        self,
        track,
        *,
        sim: SimConfig | None = None,
        car: CarConfig | None = None,
        camera: CameraConfig | None = None,
        look: Look | None = None,
    ) -> None:
        self.track = track
        self.sim = sim or SimConfig()
        self.car_config = car or CarConfig()
        self.camera_config = camera or CameraConfig()
        self.car = Car(self.car_config, gravity=self.sim.gravity)
        self._client: int | None = None
        self._lease: _renderer.PhysicsClient | None = None
        if self.sim.gui and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
            # PyBullet's GUI calls exit() when it cannot reach an X server: refuse before that
            raise RuntimeError(
                "the PyBullet GUI (render_mode='human' / SimConfig(gui=True)) needs a display, and DISPLAY is "
                "not set; use render_mode='rgb_array' (or run under xvfb-run)"
            )
        try:
            self._lease = _renderer.connect(renderer=self.sim.renderer, gui=self.sim.gui)
            self._client = self._lease.id
            self.renderer_name = self._lease.renderer
            self._build()
            self.camera = CameraSensor(self.camera_config, self._client, renderer_flag(self.renderer_name), self.sim.shadows)
            if self.camera.shadow_reuse is not None:
                self._declare_mesh_sizes(self.camera.shadow_reuse)
            self._look: Look | None = None  # the look set ...
            self._applied_look: Look | None = None  # ... and the one the scene shows (see set_look)
            self._warmed_up = False  # the first frame of a renderer's life differs (see render())
            self.set_look(look if look is not None else (REALISTIC_LOOK if self.realistic else DEFAULT_LOOK))
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ construction
    def _activate(self) -> None:
        if self._lease is None:
            raise RuntimeError("this World is closed")
        _renderer.activate(self._lease)

    def _build(self) -> None:
        self._activate()
        c = self._client
        p.resetSimulation(physicsClientId=c)
        p.setGravity(0, 0, -self.sim.gravity, physicsClientId=c)
        p.setTimeStep(1.0 / self.sim.physics_hz, physicsClientId=c)
        if self.sim.gui:
            p.configureDebugVisualizer(p.COV_ENABLE_GUI, 0, physicsClientId=c)
        track = self.track
        xy = np.asarray(track.cones_xy, dtype=np.float64)
        lo = np.minimum(xy.min(axis=0), np.asarray(track.centerline).min(axis=0)) - GROUND_MARGIN_M
        hi = np.maximum(xy.max(axis=0), np.asarray(track.centerline).max(axis=0)) + GROUND_MARGIN_M
        side = float(max(hi - lo))
        self._ground_extent = (float(lo[0]), float(lo[1]), float(lo[0]) + side, float(lo[1]) + side)
        # Bodies without a visual shape make PyBullet draw their collision shape (and crash the EGL
        # renderer for planes): physics-only bodies get this tiny visual buried under the ground.
        self._hidden_visual = p.createVisualShape(
            p.GEOM_BOX, halfExtents=[0.01, 0.01, 0.01], visualFramePosition=[0, 0, -20], physicsClientId=c
        )
        ground_col = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=c)
        self._ground = p.createMultiBody(0, ground_col, self._hidden_visual, physicsClientId=c)  # physics only
        p.changeDynamics(self._ground, -1, lateralFriction=0.8, physicsClientId=c)
        # Textures: PyBullet's per-body texture switching is broken under EGL and changeTexture does
        # nothing in DIRECT mode, so every texture comes with its mesh through an OBJ + MTL pair, and
        # the ground's visual body is swapped when the look's ground changes (shapes cached per look).
        self._ground_shapes: dict[tuple, list[int]] = {}
        self._ground_visuals: list[int] = []
        self._ground_key: tuple | None = None
        self._clutter_shapes: dict[int, int] = {}
        self._clutter_body: int | None = None
        self._clutter_key: int | None = None

        # cones: one textured visual/collision shape per class, one body per cone
        shapes = []
        self.realistic = self.sim.scene == "realistic"
        for name in CONE_CLASSES:
            tex = realistic_cone_texture(name) if self.realistic else cone_texture(name)
            f = str(mesh_file(f"cone_{name}", cone_obj(CONE_HEIGHT_M[name], CONE_BASE_M[name]), tex))
            vis = p.createVisualShape(p.GEOM_MESH, fileName=f, physicsClientId=c)
            col = p.createCollisionShape(p.GEOM_MESH, fileName=f, physicsClientId=c)
            shapes.append((vis, col))
        self.cone_classes = np.asarray(track.cone_classes, dtype=np.int64)
        self._cone_home = xy.copy()
        self._cone_bodies: list[int] = []
        # Cones are static (mass 0) until the car touches one; then it becomes a dynamic body that
        # can be knocked over. Resting cones therefore never drift, and a reset restores them exactly
        # (same seed, same bytes, also for a reused env).
        self._cone_com_z = np.empty(len(xy))
        self._cone_dynamics: list[tuple[float, list[float]]] = []
        for i, ((x, y), cls) in enumerate(zip(xy, self.cone_classes)):
            name = CONE_CLASSES[cls]
            vis, col = shapes[cls]
            h, r = CONE_HEIGHT_M[name], 0.5 * CONE_BASE_M[name]
            mass = self.sim.cone_mass * (1.5 if name == "big_orange" else 1.0)
            com_z = 0.3 * h
            inertia = [0.15 * mass * r * r + 0.0375 * mass * h * h] * 2 + [0.3 * mass * r * r]
            b = p.createMultiBody(0, col, vis, [float(x), float(y), 0.0], baseInertialFramePosition=[0, 0, com_z],
                                  physicsClientId=c)
            p.changeDynamics(b, -1, lateralFriction=0.7, restitution=0.05, physicsClientId=c)
            self._cone_bodies.append(b)
            self._cone_com_z[i] = com_z
            self._cone_dynamics.append((mass, inertia))
        self._dynamic_cones: set[int] = set()
        self._cone_tilt: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # knocked cone -> (mesh origin, rotation)

        # the car's body: a dynamic box (collision only) that the bicycle model teleports every
        # physics step, and a separate visual-only body shown in the chase view, never to the car camera
        cfg = self.car_config
        self._car_body_dx = cfg.body_center_x
        body_h = CAR_BODY_HEIGHT_M
        self._car_body_z = 0.15 + body_h / 2
        half = [cfg.length / 2, cfg.width / 2, body_h / 2]
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=c)
        self._car_body = p.createMultiBody(cfg.mass, col, self._hidden_visual, [0, 0, self._car_body_z],
                                           physicsClientId=c)
        car_obj = mesh_file("car", box_obj(cfg.length, cfg.width, body_h, z0=-body_h / 2))
        vis = p.createVisualShape(p.GEOM_MESH, fileName=str(car_obj), rgbaColor=[0.6, 0.05, 0.08, 1],
                                  physicsClientId=c)
        self._car_visual = p.createMultiBody(0, -1, vis, [0, 0, -10], physicsClientId=c)

        self._shadow_bodies: list[int] = []
        if self.realistic:  # soft contact shadows: translucent dark discs under the cones
            shadow_shapes = []
            for name in CONE_CLASSES:
                obj = mesh_file(f"shadow_{name}", scenery.shadow_disc_obj(SHADOW_DISC_SCALE * CONE_BASE_M[name]))
                shadow_shapes.append(p.createVisualShape(p.GEOM_MESH, fileName=str(obj), rgbaColor=[0, 0, 0, 0.3],
                                                         physicsClientId=c))
            for (x, y), cls in zip(xy, self.cone_classes):
                self._shadow_bodies.append(p.createMultiBody(0, -1, shadow_shapes[cls], [float(x), float(y), 0.0],
                                                             physicsClientId=c))
        self._shadow_offset = np.zeros(2)
        # cast shadows: drawn into each frame after rendering (see render() and sim.cast_shadows)
        self._caster = ShadowCaster(self.camera_config) if self.realistic and self.sim.cast_shadows else None
        self._cone_plate = np.array([cone_dimensions(CONE_HEIGHT_M[n], CONE_BASE_M[n])["plate_half"]
                                     for n in CONE_CLASSES])[self.cone_classes]
        self._cone_height = np.array([CONE_HEIGHT_M[n] for n in CONE_CLASSES])[self.cone_classes]
        self._cone_lut = np.full(1, -1, dtype=np.int32)
        self._grow_lut()
        self._cone_xy = xy.copy()
        self._lidars: dict[LidarConfig, LidarSensor] = {}

    def _declare_mesh_sizes(self, reuse: ShadowMapReuse) -> None:
        """How far the meshes of the bodies that move reach from their centre of mass (the shadow map
        is redrawn only around what moved; PyBullet does not report a mesh's size)."""
        for i, b in enumerate(self._cone_bodies):
            name = CONE_CLASSES[self.cone_classes[i]]
            reuse.declare(b, math.hypot(CONE_BASE_M[name], CONE_HEIGHT_M[name]))
        for i, b in enumerate(self._shadow_bodies):
            reuse.declare(b, SHADOW_DISC_SCALE * CONE_BASE_M[CONE_CLASSES[self.cone_classes[i]]] + 0.01)
        cfg = self.car_config
        reuse.declare(self._car_visual, math.hypot(cfg.length, cfg.width, CAR_BODY_HEIGHT_M))

    def _grow_lut(self) -> None:
        """Body id -> cone index lookup (-1 for ground, car, anything else), sized to every body id."""
        c = self._client
        n_ids = max(p.getBodyUniqueId(i, physicsClientId=c) for i in range(p.getNumBodies(physicsClientId=c))) + 2
        lut = np.full(n_ids + 1, -1, dtype=np.int32)  # the last entry stays -1: unknown ids clip onto it
        for i, b in enumerate(self._cone_bodies):
            lut[b + 1] = i
        self._cone_lut = lut

    # ------------------------------------------------------------------ appearance
    def set_look(self, look: Look) -> None:
        """Apply an appearance (textures are regenerated only when they change).

        A world that renders no camera frames (renderer "none": the cone-list scenarios) makes its
        textures only when a view first needs them (:meth:`render_chase`): building the ground and
        sky textures takes about 0.4 s per world, and training on cone lists never looks at them."""
        self._look = look
        if self.renderer_name != "none":
            self._apply_look()

    def _apply_look(self) -> None:
        """Make the scene look like ``self._look`` (see :meth:`set_look`)."""
        self._activate()
        look = self._look
        assert look is not None
        old = self._applied_look
        track = self.track
        c = self._client
        ground_key = (look.asphalt_rgb, look.grass_rgb, look.kerb_rgb, look.ground_seed)
        if ground_key != self._ground_key:
            shapes = self._ground_shapes.get(ground_key)
            if shapes is None:
                paths = (realistic_ground_files(track, self._ground_extent, look) if self.realistic
                         else [ground_file(track, self._ground_extent, look)])
                shapes = [p.createVisualShape(p.GEOM_MESH, fileName=str(f), physicsClientId=c) for f in paths]
                self._ground_shapes[ground_key] = shapes
            for b in self._ground_visuals:
                p.removeBody(b, physicsClientId=c)
            self._ground_visuals = [p.createMultiBody(0, -1, shape, physicsClientId=c) for shape in shapes]
            self._ground_key = ground_key
            self._grow_lut()
        if self.realistic:
            new_clutter = look.clutter_seed != self._clutter_key
            if new_clutter:
                shape = self._clutter_shapes.get(look.clutter_seed)
                if shape is None:
                    shape = p.createVisualShape(p.GEOM_MESH, fileName=str(clutter_file(track, look.clutter_seed)),
                                                physicsClientId=c)
                    self._clutter_shapes[look.clutter_seed] = shape
                if self._clutter_body is not None:
                    p.removeBody(self._clutter_body, physicsClientId=c)
                self._clutter_body = p.createMultiBody(0, -1, shape, physicsClientId=c)
                self._clutter_key = look.clutter_seed
                self._grow_lut()
            if new_clutter or old is None or old.clutter_tint != look.clutter_tint:
                p.changeVisualShape(self._clutter_body, -1, rgbaColor=[*look.clutter_tint, 1.0], physicsClientId=c)
            if old is None or (old.light_direction, old.ambient, old.diffuse) != (
                    look.light_direction, look.ambient, look.diffuse):
                self._place_shadows(look)
        if old is None or old.cone_shade != look.cone_shade:
            for b, cls in zip(self._cone_bodies, self.cone_classes):
                p.changeVisualShape(b, -1, rgbaColor=[*look.cone_shade[cls], 1.0], physicsClientId=c)
        if old is None or (old.sky_top_rgb, old.sky_horizon_rgb, old.cloud_cover, old.sky_seed, old.grass_rgb) != (
            look.sky_top_rgb, look.sky_horizon_rgb, look.cloud_cover, look.sky_seed, look.grass_rgb
        ):
            if self.realistic:  # finer, with a skyline (buildings, trees, poles) on the horizon
                pano = sky_panorama(look, width=4096, height=512)
                self._panorama = add_skyline(pano, look.sky_seed, ground_rgb=look.grass_rgb)
            else:
                self._panorama = sky_panorama(look)
        self.camera.set_look(look, self._panorama)
        d = np.asarray(look.light_direction, dtype=np.float64)
        self._light = {
            "lightDirection": (d / np.linalg.norm(d)).tolist(),
            "lightColor": list(look.light_color),
            "lightAmbientCoeff": look.ambient,
            "lightDiffuseCoeff": look.diffuse,
            "lightSpecularCoeff": look.specular,
        }
        self._applied_look = look

    def _place_shadows(self, look: Look) -> None:
        """Shift the contact shadows away from the sun (more for a low sun) and darken them with the
        share of direct light."""
        d = np.asarray(look.light_direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        horiz = float(np.hypot(d[0], d[1]))
        away = -d[:2] / horiz if horiz > 1e-9 else np.zeros(2)
        self._shadow_offset = away * min(0.12, 0.06 * horiz / max(d[2], 0.2))
        strength = float(np.clip(0.15 + 0.45 * look.diffuse / max(look.ambient + look.diffuse, 1e-6), 0.1, 0.5))
        c = self._client
        for i, b in enumerate(self._shadow_bodies):
            if i not in self._dynamic_cones:
                x, y = self._cone_home[i] + self._shadow_offset
                p.resetBasePositionAndOrientation(b, [float(x), float(y), 0.0], [0, 0, 0, 1], physicsClientId=c)
            p.changeVisualShape(b, -1, rgbaColor=[0, 0, 0, strength], physicsClientId=c)

    @property
    def look(self) -> Look:
        assert self._look is not None
        return self._look

    # ------------------------------------------------------------------ episode
    def reset(self, pose: tuple[float, float, float], speed: float = 0.0) -> None:
        """Put every cone back at home, standing, and the car at ``pose`` (rear axle x, y, yaw)."""
        self._activate()
        c = self._client
        for i in sorted(self._dynamic_cones):
            b = self._cone_bodies[i]
            p.changeDynamics(b, -1, mass=0, physicsClientId=c)
            x, y = self._cone_home[i]
            p.resetBasePositionAndOrientation(b, [float(x), float(y), float(self._cone_com_z[i])], [0, 0, 0, 1],
                                              physicsClientId=c)
            p.resetBaseVelocity(b, [0, 0, 0], [0, 0, 0], physicsClientId=c)
        for i in self._dynamic_cones if self._shadow_bodies else ():
            x, y = self._cone_home[i] + self._shadow_offset
            p.resetBasePositionAndOrientation(self._shadow_bodies[i], [float(x), float(y), 0.0], [0, 0, 0, 1],
                                              physicsClientId=c)
        self._dynamic_cones.clear()
        self._cone_tilt.clear()
        self._cone_xy = self._cone_home.copy()
        self.car.reset(*pose, speed=speed)
        self._place_car_body()

    def _place_car_body(self) -> None:
        x, y, yaw = self.car.pose
        bx = x + self._car_body_dx * math.cos(yaw)
        by = y + self._car_body_dx * math.sin(yaw)
        q = p.getQuaternionFromEuler([0, 0, yaw])
        vx, vy = self.car.velocity_world
        c = self._client
        p.resetBasePositionAndOrientation(self._car_body, [bx, by, self._car_body_z], q, physicsClientId=c)
        p.resetBaseVelocity(self._car_body, [vx, vy, 0], [0, 0, self.car.state.yaw_rate], physicsClientId=c)

    def _cones_out_of_reach(self) -> bool:
        """No cone can touch the car's body during the next control period, and none is moving."""
        for i in self._dynamic_cones:  # a knocked cone still moving needs the physics
            lin, ang = p.getBaseVelocity(self._cone_bodies[i], physicsClientId=self._client)
            if max(map(abs, lin)) > RESTING_SPEED or max(map(abs, ang)) > RESTING_SPEED:
                return False
        x, y, yaw = self.car.pose
        c, s = math.cos(yaw), math.sin(yaw)
        bx, by = x + self._car_body_dx * c, y + self._car_body_dx * s
        cfg, state = self.car_config, self.car.state
        period = 1.0 / self.sim.control_hz
        # how far any point of the body can move in one period: translation, plus rotation at the
        # corners, with the speed and yaw rate it could reach by then; plus a cone's base and a margin
        v_max = self.car.speed + cfg.max_accel * period
        r_max = abs(state.yaw_rate) + v_max * math.tan(cfg.max_steer) / cfg.wheelbase
        half_diag = math.hypot(cfg.length / 2, cfg.width / 2)
        margin = CONE_REACH_M + (v_max + half_diag * r_max) * period
        dx, dy = self._cone_xy[:, 0] - bx, self._cone_xy[:, 1] - by
        along, across = np.abs(dx * c + dy * s), np.abs(-dx * s + dy * c)
        near = (along < cfg.length / 2 + margin) & (across < cfg.width / 2 + margin)
        return not near.any()

    def step(self, steer: float, pedal: float, friction: float | None = None) -> set[int]:
        """Advance one control period (``substeps`` physics steps). Returns the indices of cones
        the car's body touched.

        The car follows its own dynamics; PyBullet only finds contacts with cones and moves knocked
        ones. While no cone is within reach of the body and none is moving, PyBullet has nothing to
        do, so it is not stepped (the car's state is the same either way)."""
        self._activate()
        dt = 1.0 / self.sim.physics_hz
        touched: set[int] = set()
        c = self._client
        lut = self._cone_lut
        if self._cones_out_of_reach():
            self.car.step(dt, steer, pedal, friction, n=self.sim.substeps)
            self._place_car_body()
            return touched
        for _ in range(self.sim.substeps):
            self.car.step(dt, steer, pedal, friction)
            self._place_car_body()
            p.stepSimulation(physicsClientId=c)
            for contact in p.getContactPoints(bodyA=self._car_body, physicsClientId=c):
                other = contact[2]
                if 0 <= other + 1 < lut.shape[0] and lut[other + 1] >= 0:
                    touched.add(int(lut[other + 1]))
            for i in touched - self._dynamic_cones:  # knocked: from now on a dynamic body
                mass, inertia = self._cone_dynamics[i]
                p.changeDynamics(self._cone_bodies[i], -1, mass=mass, localInertiaDiagonal=inertia, physicsClientId=c)
                self._dynamic_cones.add(i)
                if self._shadow_bodies:  # a knocked cone leaves its contact shadow behind: hide it
                    p.resetBasePositionAndOrientation(self._shadow_bodies[i], [0, 0, -20], [0, 0, 0, 1],
                                                      physicsClientId=c)
        if self._dynamic_cones:
            for i in self._dynamic_cones:
                com, quat = p.getBasePositionAndOrientation(self._cone_bodies[i], physicsClientId=c)
                self._cone_xy[i] = com[:2]
                rot = np.asarray(p.getMatrixFromQuaternion(quat), dtype=np.float64).reshape(3, 3)
                self._cone_tilt[i] = (np.asarray(com, dtype=np.float64) - rot[:, 2] * self._cone_com_z[i], rot)
        return touched

    @property
    def cone_xy(self) -> np.ndarray:
        """Current cone positions (N, 2); they move when knocked."""
        return self._cone_xy

    def cone_displacement(self) -> np.ndarray:
        """Distance of each cone from where it was placed (m)."""
        return np.hypot(*(self._cone_xy - self._cone_home).T)

    # ------------------------------------------------------------------ LiDAR
    def lidar(self, config: LidarConfig) -> LidarSensor:
        """The LiDAR ``config`` on this car (made once per config; see :mod:`weather_gym.sim.lidar`)."""
        sensor = self._lidars.get(config)
        if sensor is None:
            if self._client is None:
                raise StateError("World.lidar: the world is closed")
            cfg = self.car_config
            x0 = self._car_body_dx - cfg.length / 2
            z0 = self._car_body_z - CAR_BODY_HEIGHT_M / 2
            box = (x0, x0 + cfg.length, -cfg.width / 2, cfg.width / 2, z0, z0 + CAR_BODY_HEIGHT_M)
            sensor = LidarSensor(config, self._client, self._ground, self._car_body, box, self.cone_classes,
                                 self._cone_height)
            self._lidars[config] = sensor
        return sensor

    def lidar_scan(self, config: LidarConfig, rng: np.random.Generator | None = None, *, naive: bool = False):
        """One scan of the LiDAR ``config`` at the car's pose (a ``PointCloud``); ``rng`` draws its range
        noise (None: none); ``naive`` casts every beam through ``rayTestBatch`` (the benchmark's baseline)."""
        self._activate()
        sensor = self.lidar(config)
        frames = self._cone_tilt or None
        if naive:
            return sensor.scan_naive(self.car.pose, self._cone_xy, self._cone_lut, cone_frames=frames)
        return sensor.scan(self.car.pose, self._cone_xy, self._cone_lut, cone_frames=frames, rng=rng)

    # ------------------------------------------------------------------ lifetime
    @property
    def client(self) -> int | None:
        return self._client

    def close(self) -> None:
        """Disconnect the physics client (safe to call twice)."""
        lease, self._lease, self._client = getattr(self, "_lease", None), None, None
        _renderer.release(lease)

    def __del__(self) -> None:  # a world dropped without close(): queue its client, touch nothing now
        lease = getattr(self, "_lease", None)
        if lease is not None:
            self._lease = self._client = None
            _renderer.release(lease, deferred=True)

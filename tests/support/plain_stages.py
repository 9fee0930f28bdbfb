"""USD stages a new user would write: no denoisebench metadata at all (helpers for tests and bench/).

* :func:`author_plain_box`: a Cornell-style box (Y-up, meters): a RectLight under the ceiling,
  diffuse walls (red left, green right, white elsewhere), a matte sphere and a rough-metal sphere,
  and a camera looking in through the open front. Indirect light is a large share of the image.
* :func:`author_every_light`: one stage with every supported UsdLux light kind (rect, disk, sphere,
  point = SphereLight ``treatAsPoint``, spot = point + ShapingAPI cone, distant, dome), rough and
  smooth materials (diffuse, rough metal, smooth metal, smooth glass) and a textured floor.

Both have a static camera (one frame), so Mitsuba's own sensor sees exactly what ours does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _quad(stage, path, corners, material):
    from pxr import UsdGeom, UsdShade

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([tuple(map(float, c)) for c in corners])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    return mesh


def _surface(stage, path, color, roughness=0.5, metallic=0.0, opacity=None, ior=None):
    from pxr import Sdf, UsdShade

    material = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(tuple(map(float, color)))
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(roughness))
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(float(metallic))
    if opacity is not None:
        shader.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(float(opacity))
    if ior is not None:
        shader.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(float(ior))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material, shader


def _sphere(stage, path, center, radius, material):
    from pxr import UsdGeom, UsdShade

    sphere = UsdGeom.Sphere.Define(stage, path)
    sphere.CreateRadiusAttr(float(radius))
    sphere.AddTranslateOp().Set(tuple(map(float, center)))
    UsdShade.MaterialBindingAPI.Apply(sphere.GetPrim()).Bind(material)
    return sphere


def _camera(stage, position, focal_length=28.0):
    from pxr import UsdGeom

    camera = UsdGeom.Camera.Define(stage, "/Camera")
    camera.CreateFocalLengthAttr(float(focal_length))
    camera.CreateHorizontalApertureAttr(36.0)
    camera.CreateVerticalApertureAttr(36.0)
    camera.AddTranslateOp().Set(tuple(map(float, position)))
    return camera


def author_plain_box(path: str | Path) -> Path:
    """Write the Cornell-style box to ``path`` (a .usda); return the path."""
    from pxr import Usd, UsdGeom, UsdLux

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    white, _ = _surface(stage, "/Materials/White", (0.73, 0.73, 0.73), roughness=1.0)
    red, _ = _surface(stage, "/Materials/Red", (0.63, 0.065, 0.05), roughness=1.0)
    green, _ = _surface(stage, "/Materials/Green", (0.14, 0.45, 0.091), roughness=1.0)
    matte, _ = _surface(stage, "/Materials/Matte", (0.8, 0.6, 0.3), roughness=1.0)
    metal, _ = _surface(stage, "/Materials/RoughMetal", (0.9, 0.9, 0.9), roughness=0.35, metallic=1.0)
    s = 1.0
    _quad(stage, "/Box/Floor", [(-s, -s, s), (s, -s, s), (s, -s, -s), (-s, -s, -s)], white)
    _quad(stage, "/Box/Ceiling", [(-s, s, -s), (s, s, -s), (s, s, s), (-s, s, s)], white)
    _quad(stage, "/Box/Back", [(-s, -s, -s), (s, -s, -s), (s, s, -s), (-s, s, -s)], white)
    _quad(stage, "/Box/Left", [(-s, -s, s), (-s, -s, -s), (-s, s, -s), (-s, s, s)], red)
    _quad(stage, "/Box/Right", [(s, -s, -s), (s, -s, s), (s, s, s), (s, s, -s)], green)
    _sphere(stage, "/Objects/MatteSphere", (-0.4, -0.6, -0.2), 0.4, matte)
    _sphere(stage, "/Objects/MetalSphere", (0.45, -0.65, 0.3), 0.35, metal)
    light = UsdLux.RectLight.Define(stage, "/Lights/Ceiling")
    light.CreateWidthAttr(0.6)
    light.CreateHeightAttr(0.6)
    light.CreateIntensityAttr(15.0)
    light.CreateColorAttr((1.0, 0.9, 0.75))
    light.AddTranslateOp().Set((0.0, s - 1e-3, 0.0))
    light.AddRotateXOp().Set(-90.0)  # a RectLight emits toward its -Z: now straight down
    _camera(stage, (0.0, 0.0, 3.4), focal_length=30.0)
    stage.GetRootLayer().Save()
    return path


def _checker_png(path: Path, size: int = 16) -> None:
    from PIL import Image

    y, x = np.mgrid[0:size, 0:size]
    check = ((x // 4 + y // 4) % 2).astype(bool)
    image = np.where(check[..., None], np.array([230, 200, 60]), np.array([40, 70, 160])).astype(np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(path)


def author_every_light(path: str | Path) -> Path:
    """Write the every-light stage to ``path`` (a .usda, with textures/checker.png beside it)."""
    from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdShade

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _checker_png(path.parent / "textures" / "checker.png")
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)

    floor_material = UsdShade.Material.Define(stage, "/Materials/Checker")
    surface = UsdShade.Shader.Define(stage, "/Materials/Checker/Surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    surface.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.8)
    texture = UsdShade.Shader.Define(stage, "/Materials/Checker/Texture")
    texture.CreateIdAttr("UsdUVTexture")
    texture.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("./textures/checker.png")
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(texture.ConnectableAPI(), "rgb")
    floor_material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    floor = _quad(stage, "/Floor", [(-3, -1, 3), (3, -1, 3), (3, -1, -3), (-3, -1, -3)], floor_material)
    st = UsdGeom.PrimvarsAPI(floor).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set([(0, 0), (2, 0), (2, 2), (0, 2)])
    back, _ = _surface(stage, "/Materials/Back", (0.6, 0.6, 0.6), roughness=1.0)
    _quad(stage, "/Back", [(-3, -1, -2), (3, -1, -2), (3, 3, -2), (-3, 3, -2)], back)

    diffuse, _ = _surface(stage, "/Materials/Diffuse", (0.7, 0.3, 0.3), roughness=1.0)
    rough_metal, _ = _surface(stage, "/Materials/RoughMetal", (0.9, 0.8, 0.6), roughness=0.3, metallic=1.0)
    mirror, _ = _surface(stage, "/Materials/Mirror", (0.95, 0.95, 0.95), roughness=0.0, metallic=1.0)
    glass, _ = _surface(stage, "/Materials/Glass", (1.0, 1.0, 1.0), roughness=0.0, opacity=0.0, ior=1.5)
    _sphere(stage, "/Objects/Diffuse", (-1.5, -0.55, -0.5), 0.45, diffuse)
    _sphere(stage, "/Objects/RoughMetal", (-0.5, -0.55, -0.3), 0.45, rough_metal)
    _sphere(stage, "/Objects/Mirror", (0.5, -0.55, -0.5), 0.45, mirror)
    _sphere(stage, "/Objects/Glass", (1.5, -0.55, -0.2), 0.45, glass)

    rect = UsdLux.RectLight.Define(stage, "/Lights/Rect")
    rect.CreateWidthAttr(1.0)
    rect.CreateHeightAttr(0.5)
    rect.CreateIntensityAttr(6.0)
    rect.AddTranslateOp().Set((-1.0, 2.5, 0.0))
    rect.AddRotateXOp().Set(-90.0)
    disk = UsdLux.DiskLight.Define(stage, "/Lights/Disk")
    disk.CreateRadiusAttr(0.3)
    disk.CreateIntensityAttr(8.0)
    disk.CreateColorAttr((0.6, 0.8, 1.0))
    disk.AddTranslateOp().Set((1.2, 2.5, 0.5))
    disk.AddRotateXOp().Set(-90.0)
    sphere_light = UsdLux.SphereLight.Define(stage, "/Lights/Sphere")
    sphere_light.CreateRadiusAttr(0.15)
    sphere_light.CreateIntensityAttr(10.0)
    sphere_light.AddTranslateOp().Set((0.0, 1.2, 0.8))
    point = UsdLux.SphereLight.Define(stage, "/Lights/Point")
    point.CreateRadiusAttr(0.0)
    point.CreateIntensityAttr(20.0)
    point.AddTranslateOp().Set((2.0, 1.5, 1.0))
    spot = UsdLux.SphereLight.Define(stage, "/Lights/Spot")
    spot.CreateRadiusAttr(0.0)
    spot.CreateIntensityAttr(40.0)
    spot.AddTranslateOp().Set((-2.0, 2.0, 1.5))
    spot.AddRotateXOp().Set(-60.0)
    shaping = UsdLux.ShapingAPI.Apply(spot.GetPrim())
    shaping.CreateShapingConeAngleAttr(30.0)
    shaping.CreateShapingConeSoftnessAttr(0.3)
    distant = UsdLux.DistantLight.Define(stage, "/Lights/Sun")
    distant.CreateIntensityAttr(1.5)
    distant.CreateAngleAttr(0.53)
    distant.AddRotateXOp().Set(-50.0)
    distant.AddRotateYOp().Set(30.0)
    UsdLux.DomeLight.Define(stage, "/Lights/Sky").CreateIntensityAttr(0.3)

    _camera(stage, (0.0, 0.6, 4.5), focal_length=24.0)
    stage.GetRootLayer().Save()
    return path

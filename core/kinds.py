"""Surface kinds: the shapes the core has closed forms for, declared once.

Every module that treats shapes differently reads these codes: `inner` (the exact point-to-patch
integrals), `occlusion` and `bvh` (exact ray tests), `occluded` and `shadow` (exact shadows). A
patch's kind comes from its geometry (`Geometry.kind` for its family, `Geometry.exact_kind` for
the closed form of the integral over one patch), so a new shape declares its kind in its own
class and no dispatch elsewhere changes.
"""

GENERIC = 0  # no closed form: quadrature (inner integrals), a proxy of triangles (rays)
POLYGON = 1  # a flat quad or triangle
SPHERE = 2  # a sphere or, under any affine map, an ellipsoid (a round one for the inner integral)
DISK = 3  # a disk or annular sector (round for the inner integral)
CYLINDER = 4  # a cylinder's lateral surface (round, exact area, for the inner integral)
MESH = 5  # a triangle of a proxy or a polygon mesh (rays: `occlusion`, `bvh`)
POLYGON_MESH = 6  # a polygon mesh occluding as one object (`occlusion`)

# the order a segment's candidate occluders are tested in, cheapest first: closed forms, then a
# polygon mesh's BVH, then a proxy's tiles (a segment one of them blocks is not tested further:
# `visibility.blocked_rays`)
RAY_TEST_ORDER = ((POLYGON, SPHERE, DISK, CYLINDER), (POLYGON_MESH,), (MESH,))

NAMES = {
    GENERIC: "generic",
    POLYGON: "polygon",
    SPHERE: "sphere",
    DISK: "disk",
    CYLINDER: "cylinder",
    MESH: "mesh",
    POLYGON_MESH: "polygon mesh",
}

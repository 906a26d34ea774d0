"""Collision: rigid obstacles (signed distance functions) and cloth self-collision.

    obstacles.py       Obstacle and its kinds (Plane, Sphere, Capsule, Box, MeshObstacle),
                       poses and scripted motion
    capsule_union.py   CapsuleUnion: a body (the mannequin) as a union of capsules
    sdf_grid.py        SDFGrid: a closed triangle mesh's signed distance on a grid
    shape.py           an obstacle's shape as kernel arguments (kind id, parameters, arrays)
                       and the funcs that dispatch on the kind at run time, so every
                       collision kernel compiles once per process
    geom.py            closest points and analytic SDFs (Taichi funcs)
    collider.py        Collider: the per-substep response, and the contacts handed to the
                       strain projection as half-spaces
    self_collision.py  SelfCollision: cloth-cloth repulsion with a spatial hash
"""
from .capsule_union import CapsuleUnion
from .collider import Collider
from .obstacles import (THICKNESS, Box, Capsule, CollisionError, MeshObstacle, Obstacle, Plane,
                        Sphere, rotation_about, rotation_between)

__all__ = ["THICKNESS", "Box", "Capsule", "CapsuleUnion", "Collider", "CollisionError",
           "MeshObstacle", "Obstacle", "Plane", "Sphere", "rotation_about", "rotation_between"]

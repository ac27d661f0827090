"""Collision geometry and distances without ROS: a URDF's ``<collision>`` shapes, the
self-collision pairs (SRDF or sampled), scene obstacles, and per-cycle distances with
the velocity-damper rows the QP law (:mod:`manip_kin.control.qp`) takes as a limit.

* :mod:`~manip_kin.collision.geometry`: shapes on model frames; obstacles as shapes;
* :mod:`~manip_kin.collision.meshes`: mesh files to convex hulls (URIs: :mod:`manip_kin.core.mesh_uris`);
* :mod:`~manip_kin.collision.srdf`: an SRDF's ``disable_collisions``;
* :mod:`~manip_kin.collision.pairs`: which link pairs are checked;
* :mod:`~manip_kin.collision.collision_model`: :func:`load_collision_model`;
* :mod:`~manip_kin.collision.distances`: :class:`CollisionChecker`;
* :mod:`~manip_kin.collision.path`: :func:`first_collision_along`, for a planned path.
"""

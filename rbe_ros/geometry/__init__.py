"""Geometry: posed convex blocks, their planar faces, contact interfaces and kerns."""

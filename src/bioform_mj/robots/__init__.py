"""Robots as files: references and package paths, the MJCF and URDF formats, the layout a plant needs, preparation,
keyframes, ground-truth parameters, floor and self contacts, and the scene composed of them (design §8, §12,
§13).
"""

"""Scenes of many leaves, with no GPU: scene specs and files (:mod:`.spec`), plants and fields
(:mod:`.plants`, :mod:`.stems`), and the camera framing shared by every renderer (:mod:`.camera`).
"""

"""Colours, ranges and speeds of the viewer's controls."""

from __future__ import annotations

__all__ = ["ALPHA_RANGE", "ALPHA_STEP", "CABLE_COLOUR", "FIXED_COLOUR", "REST_COLOUR", "WIREFRAME_THICKNESS",
           "SPEEDS", "PLAYBACK_FPS", "SIMULATE_LABEL", "DRAG_COLOUR", "DRAG_STIFFNESS_PER_MU", "DRAG_ITERATIONS",
           "DRAG_TOLERANCE", "PULL_RANGE_FRACTION", "PULL_STEP_FRACTION", "TENSION_RANGE_PER_MU_AREA",
           "SLIDER_DIVISIONS", "SLACK_COLOUR", "OBSTACLE_COLOUR", "OBSTACLE_OPACITY", "PLANE_EXTENT", "ARROW_COLOUR",
           "ARROW_LENGTH", "ARROW_HEAD", "ARROW_SHAFT", "ARROW_THRESHOLD"]

#: Actuation range of the cable sliders (widened to include a scene's own actuation).
ALPHA_RANGE = (0.3, 1.2)
ALPHA_STEP = 0.005
CABLE_COLOUR = (220, 40, 40)
#: A slack tendon (no tension) is drawn grey instead of red.
SLACK_COLOUR = (150, 150, 150)
#: Top of a tendon's pull slider as a fraction of its rest length (sf.control's default bound).
PULL_RANGE_FRACTION = 0.25
#: Largest pull step of a slider move in the mixed formulation, as a fraction of the tendon's rest
#: length (sf.actuate's default step; alpha moves by sorofem.cables.DEFAULT_ALPHA_STEP).
PULL_STEP_FRACTION = 0.05
#: Top of a tendon's tension slider, when its command gives no scale, as a multiple of the mean
#: shear modulus times the body's cross-section (N; some 10 % strain of a bar of that section).
TENSION_RANGE_PER_MU_AREA = 0.2
#: At least this many positions over a pull or tension slider's range (its step is a power of ten).
SLIDER_DIVISIONS = 100
#: Obstacles: a translucent grey; a plane is drawn as a quad of half-sizes PLANE_EXTENT times
#: the body's extents around it.
OBSTACLE_COLOUR = (140, 140, 155)
OBSTACLE_OPACITY = 0.35
PLANE_EXTENT = 1.0
#: Contact force arrows: colour, the largest one's length at most, the head's length and the
#: shaft's radius, as fractions of the body's size, and the smallest force drawn as a fraction of
#: the largest (lighter ones are the barrier's far tail).
ARROW_COLOUR = (20, 20, 20)
ARROW_LENGTH = 0.15
ARROW_HEAD = 0.02
ARROW_SHAFT = 0.002
ARROW_THRESHOLD = 1e-3
FIXED_COLOUR = (40, 90, 230)
REST_COLOUR = (180, 180, 180)
#: Line width of the coloured wireframes, pixels.
WIREFRAME_THICKNESS = 1.5
#: Playback speeds offered, in multiples of real time.
SPEEDS = (0.01, 0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 100.0)
#: Most frames per second the playback sends to the browser (denser frames are skipped).
PLAYBACK_FPS = 30.0
#: Label of the scene view's button that simulates the scene's [dynamics] and plays the motion.
SIMULATE_LABEL = "simulate [dynamics]"
#: The spring of a pulled node (shift + drag): its colour, its stiffness as a multiple of the
#: mean shear modulus times the body's size (N/m; 0.1 is firm without pinning the node), and its
#: force iteration's limit and relative tolerance.
DRAG_COLOUR = (240, 150, 20)
DRAG_STIFFNESS_PER_MU = 0.1
DRAG_ITERATIONS = 12
DRAG_TOLERANCE = 1e-6

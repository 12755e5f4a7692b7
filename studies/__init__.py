"""The studies: each command is a module here (`python -m studies.<command>`, or `broadphase <command>`);
the code they share is in `studies.lib`. `python -m studies` lists the commands."""

# The commands in the order a new user meets them: name -> what it answers.
COMMANDS = {
    "compare": "every broad phase on one stepped scene, timed per stage and checked pair by pair",
    "recommend": "which broad phase should my project use for this scene?",
    "show": "a picture of what a broad phase does on a scene",
    "essay": "the essay's experiments and open questions, redone",
    "stress": "stiff and extreme scenes: which backend breaks, and how",
    "scenes": "every backend on every scene family, the essay's motion and recorded (pile, rain, ...)",
    "boxes": "every backend on the box families, as boxes and as their bounding circles",
    "queries": "rays, box and point queries a frame, timed beside the pairs and checked",
    "scale": "how each backend's cost per frame grows with n, up to 2^20",
    "bench": "our backends against the speed targets on this machine",
    "tune": "sweep each backend's parameters on a scene; check our defaults",
    "tradeoff": "error against run time for every setting of every backend, with the Pareto frontier",
}

"""Pure core: designs, materials, the model ladder and kinematics. Never imports rclpy."""

# model selection registers the rung chooser "auto" with the ladder (core/models), so that
# make_model("auto", ...) works whichever core module was imported first
from . import model_selection  # noqa: F401,E402

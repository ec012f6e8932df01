"""Motion-capture files (BVH, ASF/AMC) as MotionClips, and retargeting onto a target armature."""
from .clip import MotionClip, MotionFileError, euler_matrix
from .bvh import read_bvh
from .asf_amc import read_asf_amc
from .retarget import CMU_NAME_TABLE, RetargetError, RetargetResult, cmu_name_map, retarget

__all__ = ["MotionClip", "MotionFileError", "euler_matrix", "read_bvh", "read_asf_amc",
           "CMU_NAME_TABLE", "RetargetError", "RetargetResult", "cmu_name_map", "retarget"]

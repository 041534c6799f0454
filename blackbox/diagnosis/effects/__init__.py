"""The effect families a diagnosis can add, one module each, registered by name.

Registration order is listing order: the connection families cut the split deck in this order
(their cut pairs and new grids are numbered so), then the others list their candidates.
"""

from blackbox.diagnosis.effects.base import CandidateContext, CandidateLimit, Effect
from blackbox.diagnosis.effects.connection import Connection
from blackbox.diagnosis.effects.registry import families, get, kinds, register

# the families, in listing order (importing a module registers its class)
from blackbox.diagnosis.effects.undeclared_joint import UndeclaredJoint  # noqa: E402
from blackbox.diagnosis.effects.joint_translation import JointTranslation  # noqa: E402
from blackbox.diagnosis.effects.support_flexibility import SupportFlexibility  # noqa: E402
from blackbox.diagnosis.effects.joint_coupling import JointCoupling  # noqa: E402
from blackbox.diagnosis.effects.member_stiffness import MemberStiffness  # noqa: E402
from blackbox.diagnosis.effects.joint_gap import JointGap  # noqa: E402
from blackbox.diagnosis.effects.joint_softening import JointSoftening  # noqa: E402
from blackbox.diagnosis.effects.joint_unloading import JointUnloading  # noqa: E402
from blackbox.diagnosis.effects.p_delta import PDelta, Preload  # noqa: E402
from blackbox.diagnosis.effects.load_scale import LoadScale  # noqa: E402
from blackbox.diagnosis.effects.sensor_gain import SensorGain  # noqa: E402
from blackbox.diagnosis.effects.sensor_offset import SensorOffset  # noqa: E402
from blackbox.diagnosis.effects.outlier import Outlier  # noqa: E402
from blackbox.diagnosis.effects.sign_flip import SignFlip  # noqa: E402
from blackbox.diagnosis.effects.channel_swap import ChannelSwap  # noqa: E402
from blackbox.diagnosis.effects.misplaced_sensor import MisplacedSensor  # noqa: E402
from blackbox.diagnosis.effects.bad_channel import BadChannel  # noqa: E402
from blackbox.diagnosis.effects.bad_case import BadCase  # noqa: E402
from blackbox.diagnosis.effects.rigid_motion import RigidMotion  # noqa: E402
from blackbox.diagnosis.effects.rigid_end_zone import RigidEndZone  # noqa: E402
from blackbox.diagnosis.effects.support_fixity import SupportFixity  # noqa: E402
from blackbox.diagnosis.effects.case_swap import CaseSwap  # noqa: E402
from blackbox.diagnosis.effects.load_tilt import LoadTilt  # noqa: E402
from blackbox.diagnosis.effects.case_tilt import CaseTilt  # noqa: E402
from blackbox.diagnosis.effects.misplaced_load import MisplacedLoad  # noqa: E402
from blackbox.diagnosis.effects.load_cell import LoadCell  # noqa: E402

__all__ = ["CandidateContext", "CandidateLimit", "Effect", "Connection", "register", "get", "kinds", "families",
           "UndeclaredJoint", "JointTranslation", "SupportFlexibility", "JointCoupling", "MemberStiffness", "JointGap",
           "JointSoftening", "JointUnloading", "PDelta", "Preload", "LoadScale", "SensorGain", "SensorOffset", "Outlier",
           "SignFlip", "ChannelSwap", "MisplacedSensor", "BadChannel", "BadCase", "RigidMotion", "RigidEndZone",
           "SupportFixity", "CaseSwap", "LoadTilt", "CaseTilt", "MisplacedLoad", "LoadCell"]

"""The message layer: every topic (name, type, QoS), every message built and decoded, the
assembly of heard agents into group arrays, and the run record.  Nothing else touches messages.
"""

# ruff: noqa: F401
from .codec import (
    FIELDS,
    FLAG_STOP,
    HEADER,
    MAX_ABS,
    PROJECTION_STAGE_TOL,  # noqa: F401
    ROTATION_TOL,
    STAGE_FORMAT,
    STAMP_SLACK,
    Received,
    Stage,
    array_to_state,
    decode_pose_msg,
    decode_stage,
    decode_twist_msg,
    encode_stage,
    orthogonality,
    pose_fields,
    pose_message,
    pose_to_state,
    rot_from_values,
    rot_size,
    rot_values,
    stamp_of,
    time_key,
    twist_fields,
    twist_message,
    twist_to_state,
)
from .ensemble import Row, assemble  # noqa: F401
from .record import RECORD_KEY, RunRecord, drop_summary, run_records  # noqa: F401
from .topics import (
    DEFAULT_ENSEMBLE,
    TOPICS,
    Topic,
    full_name,
    message_type,  # noqa: F401
    namespace,
    publisher,
    qos_profiles,
    subscription,
    topic_name,
)

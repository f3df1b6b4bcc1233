"""The message layer: every topic (name, type, QoS), every message built and decoded, the
assembly of heard agents into group arrays, and the run record.  Nothing else touches messages.
"""

# ruff: noqa: F401
from .codec import (
    BLOCK_FORMAT,
    FIELDS,
    FLAG_STOP,
    HEADER,
    MAX_ABS,
    PROJECTION_STAGE_TOL,  # noqa: F401
    ROTATION_TOL,
    STAGE_FORMAT,
    STAMP_SLACK,
    Stage,
    StageRows,
    decode_block,
    decode_stage,
    encode_block,
    encode_stage,
    orthogonality,
    rot_from_values,
    rot_size,
    rot_values,
    stamp_of,
    time_key,
)
from .ensemble import Row, assemble, assemble_rows  # noqa: F401
from .exchange import (
    EXCHANGE_BLOCK_FORMAT,
    EXCHANGE_FORMAT,
    Motion,
    decode_exchange,
    decode_exchange_block,
    encode_exchange,
    encode_exchange_block,
)
from .motion import (
    MOTIONS,
    Received,
    array_to_state,
    decode_motion,
    decode_pose_msg,
    decode_twist_msg,
    motion_message,
    pose_fields,
    pose_message,
    pose_to_state,
    twist_fields,
    twist_message,
    twist_to_state,
)
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

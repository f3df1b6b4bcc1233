"""The message layer: every topic (name, type, QoS), every message built and decoded, the
assembly of heard agents into group arrays, and the run record.  Nothing else touches messages.
The run's own messages are the ``polymatch_interfaces`` package's (``.msg`` files).
"""

# ruff: noqa: F401
from .assembly import Row, assemble, assemble_rows, state_of
from .exchange import (
    Motion,
    decode_exchange,
    decode_exchange_block,
    decode_exchanges,
    encode_exchange,
    encode_exchange_block,
)
from .modes import BLOCK_MODES, MODES, MONITOR_MODES, Mode, mode_of
from .motion import (
    MOTIONS,
    Received,
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
from .run_record import RECORD_KEY, RunRecord, drop_summary, echoed_run_records, run_records
from .stage_rows import (
    FIELDS,
    FLAG_STOP,
    MAX_ABS,
    PROJECTION_STAGE_TOL,
    ROTATION_TOL,
    STAMP_SLACK,
    Stage,
    StageRows,
    decode_agent_rows,
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
from .topics import (
    DEFAULT_ENSEMBLE,
    TOPICS,
    Topic,
    full_name,
    message_type,
    namespace,
    publisher,
    qos_profiles,
    subscription,
    topic_name,
)

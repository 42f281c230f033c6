"""Synthetic rosbag2 MCAP bags: the paper's examples and drivetrains, with their truth.

All write ``/command`` (``std_msgs/Float64MultiArray``, logged at the command's time) and
``/encoder`` (``sensor_msgs/JointState`` stamped at the sample time, logged 0.1-0.3 ms later,
as a recorder receives it), so that a replay with the default parameters
(``stamp_source = "header"``) sees the same samples the simulation used.

* :func:`write_example_bag`: one command and one encoder message per sample of the paper's
  Example 1-4 (its input range, model and SNR), at 1 kHz.
* :func:`write_drivetrain_bag`: the encoder at 1 kHz; the command at 100-1000 Hz (random
  intervals of 1-10 ms with 0-0.2 ms jitter), held between messages; Example 1's curved
  branches whose dead-zone widths ``c_L``, ``c_R`` grow linearly by ``wear`` over the record;
  white noise at SNR 25. The command carries a second joint's element and the encoder a
  second joint, so ``command_index`` and ``joint`` matter (the drivetrain is element 0 and
  joint ``drive_joint``, the defaults). The paper-style random input: a new uniform value
  at every command.
* :func:`write_operation_bag`: a drivetrain in normal operation
  (:func:`genbacklash_core.scenarios.operation_record`): smooth point-to-point moves, dwells
  and jogs (or one-way traverses, pick-and-place cycles, sine sweeps, chained as phases),
  100 Hz position commands held by the servo, a 1 kHz encoder quantised to 4096 counts/rev
  whose readings are stamped at their (jittered) sampling instants and sometimes lost (a
  lost reading is absent from the bag), and optionally wearing dead zones.

Every bag stores its truth in the rosbag2 metadata (``custom_data``, key
:data:`TRUTH_KEY`, a JSON object; :class:`BagTruth`): the model at the start and at the end
of the record, the true dead zones over time, the scenario's settings and seed. A report
reads it back with :func:`read_truth` to draw the true gap and to judge compensation
against the true drivetrain.
"""

from __future__ import annotations

from .arm import ARM_TRUTH_KEY, arm_messages, write_arm_bag
from .feed import FedRecord, feed_record
from .layout import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    JOINT,
    MOTOR_TOPIC,
    START_NS,
    SimulatedBag,
    command_message,
)
from .operation import operation_settings, phases_label, write_operation_bag, write_record_bag
from .paper import write_drivetrain_bag, write_example_bag
from .truth import TRUTH_KEY, TRUTH_STEP_S, BagTruth, read_truth, settings_dict

__all__ = [
    "ARM_TRUTH_KEY",
    "COMMAND_TOPIC",
    "ENCODER_TOPIC",
    "JOINT",
    "MOTOR_TOPIC",
    "START_NS",
    "TRUTH_KEY",
    "TRUTH_STEP_S",
    "BagTruth",
    "FedRecord",
    "SimulatedBag",
    "arm_messages",
    "command_message",
    "feed_record",
    "operation_settings",
    "phases_label",
    "read_truth",
    "settings_dict",
    "write_arm_bag",
    "write_drivetrain_bag",
    "write_example_bag",
    "write_operation_bag",
    "write_record_bag",
]

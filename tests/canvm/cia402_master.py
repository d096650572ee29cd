"""A CiA 402 master written with python-canopen's RemoteNode + BaseNode402 profile, against the
project's emulated drive (`frictl sim serve --backend can --protocol cia402`).

With the drive's EDS file (config/cia402_frictionless.eds): waits for the boot-up, NMT
pre-operational, SDO reads of the identity 0x1018, the device name 0x1008 (segmented upload), the
scales and the PDO mapping (BaseNode402.setup_402_state_machine), CST by SDO, NMT operational with
a SYNC producer and RPDO1 sent cyclically, the state machine to OPERATION ENABLED (controlword over
RPDO1, statusword from TPDO1), CST torque in both directions (the plant moves), a fault (written to the emulation's test
object 0x2F00: the drive sends its EMCY) and BaseNode402.reset_from_fault, then quick stop and NMT
stop.

Usage: python3 cia402_master.py --iface vcan0 --node 1 --eds config/cia402_frictionless.eds
Prints `listening` once it waits for the boot-up, then one `key=value` line per result:
identity, device name, mappings, states, positions and torques; exits non-zero on an error.
"""

import argparse
import sys
import time

import canopen
from canopen.profiles.p402 import BaseNode402


# The SYNC and RPDO period [s], and how long a commanded torque may take to come back.
PERIOD_S = 0.04
SETTLE_TIMEOUT_S = 20.0


def say(key, value):
    sys.stdout.write("%s=%s\n" % (key, value))
    sys.stdout.flush()


def read(var, attempts=3):
    """An SDO upload, retried: in the emulated VM a frame can miss its deadline."""
    for k in range(attempts):
        try:
            return var.raw
        except canopen.SdoCommunicationError:
            if k == attempts - 1:
                raise


def mapping(pdo_map):
    return "+".join("%04X:%02X" % (v.index, v.subindex) for v in pdo_map)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--iface", default="vcan0")
    p.add_argument("--node", type=int, default=1)
    p.add_argument("--eds", required=True)
    p.add_argument("--torque-permille", type=int, default=250)
    args = p.parse_args()

    net = canopen.Network()
    net.connect(interface="socketcan", channel=args.iface)
    node = BaseNode402(args.node, args.eds)
    # The VM emulates its CPU: the profile's sub-second waits are too short there.
    node.TIMEOUT_SWITCH_STATE_SINGLE = 2.0
    node.TIMEOUT_SWITCH_STATE_FINAL = 5.0
    node.TIMEOUT_SWITCH_OP_MODE = 2.0
    node.TIMEOUT_CHECK_TPDO = 1.0
    node.TIMEOUT_RESET_FAULT = 1.0
    node.sdo.RESPONSE_TIMEOUT = 2.0
    net.add_node(node)
    sys.stdout.write("listening\n")
    sys.stdout.flush()
    node.nmt.wait_for_bootup(30)
    say("bootup", "ok")

    node.nmt.state = "PRE-OPERATIONAL"
    say("vendor", "0x%08X" % node.sdo[0x1018][1].raw)
    say("product", "0x%08X" % node.sdo[0x1018][2].raw)
    say("revision", "0x%08X" % node.sdo[0x1018][3].raw)
    say("serial", "0x%08X" % node.sdo[0x1018][4].raw)
    say("device_type", "0x%08X" % node.sdo[0x1000].raw)
    say("device_name", node.sdo[0x1008].raw)
    say("rated_torque_mnm", node.sdo[0x6076].raw)
    say("counts_per_rev", node.sdo[0x608F][1].raw)
    say("supported_modes", "0x%08X" % node.sdo[0x6502].raw)
    node.sdo[0x1017].raw = 200

    # PDO configuration by SDO (BaseNode402 finds the controlword / statusword in it).
    node.setup_402_state_machine(read_pdos=True)
    for n, m in node.rpdo.map.items():
        if m.enabled:
            say("rpdo%d" % n, "0x%03X:%s" % (m.cob_id, mapping(m)))
    for n, m in node.tpdo.map.items():
        if m.enabled:
            say("tpdo%d" % n, "0x%03X:%s" % (m.cob_id, mapping(m)))

    node.op_mode = "CYCLIC SYNCHRONOUS TORQUE"
    say("op_mode", node.sdo[0x6061].raw)

    node.nmt.state = "OPERATIONAL"
    # The SYNC producer (the drive sends its TPDOs and applies RPDOs at each SYNC), at 25 Hz: the
    # VM emulates its CPU, and Python must keep up with every frame it receives (its own SYNC and
    # RPDO frames come back to it too); behind, it reads stale values and the kernel drops the rest.
    net.sync.start(PERIOD_S)
    node.tpdo[1].wait_for_reception(5)
    say("state_start", node.state)

    # RPDO1 (controlword + target torque) sent cyclically, applied by the drive at each SYNC;
    # BaseNode402's controlword setter updates the cyclic frame.
    target = node.rpdo_pointers[0x6071]
    rpdo1 = target.pdo_parent
    target.raw = 0
    node.rpdo_pointers[0x6040].raw = 0x0000
    rpdo1.start(PERIOD_S)
    node.state = "OPERATION ENABLED"
    say("state_enabled", node.state)

    def hold(permille, seconds):
        """Commands `permille` until the drive reports it back as torque actual (within 3 %, or
        a timeout: the VM may lag), then `seconds` more; returns position and torque actual."""
        target.raw = permille
        t_end = time.monotonic() + SETTLE_TIMEOUT_S
        while time.monotonic() < t_end:
            node.tpdo[1].wait_for_reception(2.0)
            if abs(node.tpdo_values[0x6077] - permille) <= 30:
                break
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            node.check_statusword(2.0)
        node.tpdo[2].wait_for_reception(2.0)
        return node.tpdo_values[0x6064], node.tpdo_values[0x6077]

    p0 = node.tpdo_values[0x6064]
    p1, t1 = hold(args.torque_permille, 0.5)
    p2, t2 = hold(-args.torque_permille, 1.0)
    p3, t3 = hold(0, 1.0)
    say("position_start", p0)
    say("position_after_plus", p1)
    say("torque_actual_plus", t1)
    say("position_after_minus", p2)
    say("torque_actual_minus", t2)
    say("torque_actual_zero", t3)

    # A fault: the drive's EMCY reaches the EMCY consumer, the statusword shows FAULT.
    node.sdo[0x2F00].raw = 0x2310
    t_end = time.monotonic() + 5
    while not node.emcy.active and time.monotonic() < t_end:
        time.sleep(0.01)
    say("emcy", ",".join("0x%04X" % e.code for e in node.emcy.active))
    t_end = time.monotonic() + 5
    while not node.is_faulted() and time.monotonic() < t_end:
        node.check_statusword(2.0)
    say("state_fault", node.state)
    say("error_code", "0x%04X" % read(node.sdo[0x603F]))
    node.reset_from_fault()
    say("state_reset", node.state)
    say("emcy_active", len(node.emcy.active))
    say("error_code_after", "0x%04X" % read(node.sdo[0x603F]))

    node.controlword = 0x0002  # quick stop
    node.state = "SWITCH ON DISABLED"
    say("state_end", node.state)
    rpdo1.stop()
    net.sync.stop()
    node.nmt.state = "STOPPED"
    net.disconnect()
    say("done", "ok")


if __name__ == "__main__":
    main()

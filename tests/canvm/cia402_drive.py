"""A minimal CiA 402 servo drive built on python-canopen's LocalNode, for frictiond to drive.

The object dictionary comes from an EDS file (config/cia402_frictionless.eds); python-canopen
provides the SDO server, the NMT slave with its heartbeat producer (0x1017), the PDOs (read from
the dictionary the master wrote when the node enters operational) and the EMCY producer. This
script adds what a drive's firmware does: the CiA 402 state machine (controlword 0x6040 ->
statusword 0x6041), cyclic synchronous torque (target torque 0x6071 applied at the SYNC after
the RPDO, reported as torque actual 0x6077), and a 1-DoF motor-side plant that integrates the
applied torque (J dw/dt = tau - b w) into position 0x6064 [increments], velocity 0x606C
[increments/s] and the joint-side encoder 0x60E4:01.

Usage: python3 cia402_drive.py --iface vcan0 --node 1 --eds config/cia402_frictionless.eds
Commands on stdin (one per line): `fault CODE` (fault with an EMCY), `mute` / `unmute` (stop /
restart the heartbeat), `quit`. Events on stdout, one per line, flushed:
`boot`, `nmt STATE`, `pdos rpdo=COBID:INDEX+… tpdo=…` (the mapping read at the start),
`state STATE`, `rx cw=0x.... torque=N` (an RPDO1 whose controlword or
torque differs from the previous one), `applied torque=N` (a change of the torque the drive
applies), `emcy CODE`, `muted` / `unmuted`, and at exit
`syncs=N tpdos=N position=COUNTS`.
"""

import argparse
import math
import socket
import struct
import sys
import threading

import canopen

# CiA 402 states: name -> statusword bits (with bit 9 "remote").
SW = {
    "NOT READY TO SWITCH ON": 0x0000,
    "SWITCH ON DISABLED": 0x0040,
    "READY TO SWITCH ON": 0x0021,
    "SWITCHED ON": 0x0023,
    "OPERATION ENABLED": 0x0027,
    "QUICK STOP ACTIVE": 0x0007,
    "FAULT REACTION ACTIVE": 0x000F,
    "FAULT": 0x0008,
}


def next_state(state, cw, reset_edge):
    """The CiA 402 device control state machine (transitions 2-16)."""
    if state == "FAULT":
        return "SWITCH ON DISABLED" if reset_edge else state
    disable_voltage = cw & 0x0002 == 0
    quick_stop = cw & 0x0006 == 0x0002
    shutdown = cw & 0x0087 == 0x0006
    switch_on = cw & 0x008F == 0x0007
    enable = cw & 0x008F == 0x000F
    if state == "SWITCH ON DISABLED":
        return "READY TO SWITCH ON" if shutdown else state
    if state == "READY TO SWITCH ON":
        if disable_voltage or quick_stop:
            return "SWITCH ON DISABLED"
        return "SWITCHED ON" if switch_on or enable else state
    if state == "SWITCHED ON":
        if disable_voltage or quick_stop:
            return "SWITCH ON DISABLED"
        if shutdown:
            return "READY TO SWITCH ON"
        return "OPERATION ENABLED" if enable else state
    if state == "OPERATION ENABLED":
        if disable_voltage:
            return "SWITCH ON DISABLED"
        if quick_stop:
            return "QUICK STOP ACTIVE"
        if shutdown:
            return "READY TO SWITCH ON"
        return "SWITCHED ON" if switch_on else state
    if state == "QUICK STOP ACTIVE":
        # Quick stop option code 2 (the EDS default): stop, then switch on disabled.
        return "SWITCH ON DISABLED"
    return state


class Drive:
    def __init__(self, args):
        self.out_lock = threading.Lock()
        self.od_cache = {}
        self.net = canopen.Network()
        self.node = canopen.LocalNode(args.node, args.eds)
        self.net.add_node(self.node)
        self.state = "NOT READY TO SWITCH ON"
        self.last_cw = 0
        self.last_rx = None
        self.applied_pm = 0
        self.syncs = 0
        self.tpdos = 0
        self.pending = {}
        self.rpdo_maps = []
        self.tpdo_maps = []
        self.nmt_state = None
        # The SYNC handler (python-can's notifier thread) and the stdin commands (main thread) both
        # change the 402 state: one at a time, or a fault can be overwritten mid-SYNC.
        self.lock = threading.Lock()
        # Plant (motor side): inertia [kg m^2], viscous damping [Nm s/rad].
        self.j_kgm2 = args.inertia_kgm2
        self.b_nms = args.damping_nms
        self.gear = args.gear_ratio
        self.sync_period_s = args.sync_period_s
        self.joint_cpr = args.joint_counts_per_rev
        self.theta_rad = 0.0
        self.omega_rad_s = 0.0
        # Only this node's frames (NMT, SYNC, its RPDOs and SDO requests), into a large receive
        # buffer: the kernel drops frames silently when a reader falls behind, and Python in the
        # emulated VM does at 1 kHz.
        own = [0x000, 0x080, 0x600 + args.node] + [b + args.node for b in (0x200, 0x300, 0x400, 0x500)]
        self.net.connect(interface=args.interface, channel=args.iface,
                         can_filters=[{"can_id": i, "can_mask": 0x7FF} for i in own])
        sock = getattr(self.net.bus, "socket", None)
        if sock is not None:
            try:
                sock.setsockopt(socket.SOL_SOCKET, 33, 32 << 20)  # SO_RCVBUFFORCE (root)
            except OSError:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 32 << 20)
        self.node.add_write_callback(self.on_write)
        self.net.subscribe(0x000, self.on_nmt)
        self.net.subscribe(0x080, self.on_sync)
        self.set(0x6041, 0, self.statusword())
        # A drive whose stored configuration has a heartbeat (seen by a master started later): the
        # stored value, not an SDO write, so it starts with the boot-up.
        self.node.data_store.setdefault(0x1017, {})[0] = struct.pack("<H", args.heartbeat_ms)

    def say(self, line):
        with self.out_lock:
            sys.stdout.write(line + "\n")
            sys.stdout.flush()

    def od(self, index, sub=0):
        """The dictionary entry index:sub."""
        key = (index, sub)
        var = self.od_cache.get(key)
        if var is None:
            obj = self.node.object_dictionary[index]
            var = obj if isinstance(obj, canopen.objectdictionary.ODVariable) else obj[sub]
            self.od_cache[key] = var
        return var

    def get(self, index, sub=0):
        """A value of the local dictionary: what the master wrote by SDO, else the EDS default
        (the store python-canopen's SDO server reads and writes)."""
        raw = self.node.data_store.get(index, {}).get(sub)
        var = self.od(index, sub)
        return var.default if raw is None else var.decode_raw(raw)

    def set(self, index, sub, value):
        """Stores a value the drive produced (no SDO write callbacks run)."""
        self.node.data_store.setdefault(index, {})[sub] = self.od(index, sub).encode_raw(value)

    def statusword(self):
        sw = SW[self.state] | 0x0200
        if self.state == "OPERATION ENABLED":
            sw |= 0x1000
        return sw

    def enter(self, state):
        if state != self.state:
            self.state = state
            self.say("state " + state)
        self.set(0x6041, 0, self.statusword())

    def boot(self):
        # Initialising -> boot-up frame -> pre-operational (python-canopen's NMT slave).
        self.node.nmt.state = "INITIALISING"
        self.node.nmt.state = "PRE-OPERATIONAL"
        self.enter("SWITCH ON DISABLED")
        self.say("boot")

    def on_write(self, index, subindex, od, data):
        # The mode display follows the mode of operation (all modes of 0x6502 switch at once).
        if index == 0x6060:
            self.node.data_store.setdefault(0x6061, {})[0] = bytes(data)

    def on_nmt(self, can_id, data, timestamp):
        # python-canopen's NMT slave already applied the command; follow its state.
        state = self.node.nmt.state
        if state != self.nmt_state:
            self.nmt_state = state
            self.say("nmt " + state)
            if state == "OPERATIONAL":
                self.setup_pdos()

    def setup_pdos(self):
        """The PDO configuration the master wrote into the dictionary (python-canopen PdoMaps;
        read once, at the first start)."""
        if self.rpdo_maps or self.tpdo_maps:
            return
        self.node.rpdo.read()
        self.node.tpdo.read()
        self.rpdo_maps = [m for m in self.node.rpdo.map.values() if m.enabled]
        self.tpdo_maps = [m for m in self.node.tpdo.map.values() if m.enabled]
        for m in self.rpdo_maps:
            m.add_callback(self.on_rpdo)
        self.say("pdos rpdo=%s tpdo=%s" % (
            ",".join("0x%03X:%s" % (m.cob_id, "+".join("%04X" % v.index for v in m))
                     for m in self.rpdo_maps),
            ",".join("0x%03X:%s" % (m.cob_id, "+".join("%04X" % v.index for v in m))
                     for m in self.tpdo_maps)))

    def on_rpdo(self, pdo_map):
        # Transmission type 1: the values take effect at the next SYNC.
        values = {(v.index, v.subindex): v.raw for v in pdo_map}
        self.pending.update(values)
        rx = (values.get((0x6040, 0)), values.get((0x6071, 0)))
        if rx != self.last_rx:
            self.last_rx = rx
            self.say("rx cw=0x%04X torque=%d" % (rx[0] or 0, rx[1] or 0))

    def on_sync(self, can_id, data, timestamp):
        with self.lock:
            self.sync_locked()

    def sync_locked(self):
        if self.node.nmt.state != "OPERATIONAL":
            return
        self.syncs += 1
        pending, self.pending = self.pending, {}
        for (index, sub), value in pending.items():
            self.set(index, sub, value)
        cw = self.get(0x6040)
        edge = cw & 0x80 and not self.last_cw & 0x80
        self.last_cw = cw
        before = self.state
        self.enter(next_state(self.state, cw, edge))
        if before == "FAULT" and self.state != "FAULT":
            self.set(0x603F, 0, 0)
            self.set(0x1001, 0, 0)
            self.node.emcy.reset()
        # CST: the target torque [per mille of 0x6076] acts in operation enabled.
        pm = 0
        if self.state == "OPERATION ENABLED" and self.get(0x6061) == 10:
            max_pm = self.get(0x6072)
            pm = max(-max_pm, min(max_pm, self.get(0x6071) + self.get(0x60B2)))
        if pm != self.applied_pm:
            self.applied_pm = pm
            self.say("applied torque=%d" % pm)
        # The plant, one SYNC period on.
        tau_nm = pm * self.get(0x6076) / 1e6
        dt = self.sync_period_s
        self.omega_rad_s += dt * (tau_nm - self.b_nms * self.omega_rad_s) / self.j_kgm2
        self.theta_rad += dt * self.omega_rad_s
        cpr = self.get(0x608F, 1) / self.get(0x608F, 2)
        counts = lambda rad, per_rev: int(round(rad * per_rev / (2 * math.pi)))
        self.set(0x6064, 0, counts(self.theta_rad, cpr))
        self.set(0x606C, 0, counts(self.omega_rad_s, cpr))
        self.set(0x6077, 0, pm)
        self.set(0x60E4, 1, counts(self.theta_rad / self.gear, self.joint_cpr))
        for m in self.tpdo_maps:
            if m.trans_type and 1 <= m.trans_type <= 240 and self.syncs % m.trans_type == 0:
                for v in m:
                    v.raw = self.get(v.index, v.subindex)
                m.transmit()
                self.tpdos += 1

    def fault(self, code):
        with self.lock:
            self.fault_locked(code)

    def fault_locked(self, code):
        self.enter("FAULT")
        self.set(0x603F, 0, code)
        self.set(0x1001, 0, 1)
        self.node.emcy.send(code, 1)
        self.say("emcy 0x%04X" % code)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--iface", default="vcan0")
    p.add_argument("--interface", default="socketcan", help="python-can interface")
    p.add_argument("--node", type=int, default=1)
    p.add_argument("--eds", required=True)
    p.add_argument("--heartbeat-ms", type=int, default=100)
    p.add_argument("--sync-period-s", type=float, default=1e-3, help="the master's SYNC period")
    p.add_argument("--inertia-kgm2", type=float, default=2e-4)
    p.add_argument("--damping-nms", type=float, default=2e-3)
    p.add_argument("--gear-ratio", type=float, default=-100.0)
    p.add_argument("--joint-counts-per-rev", type=float, default=524288.0)
    args = p.parse_args()
    d = Drive(args)
    d.boot()
    for line in sys.stdin:
        words = line.split()
        if not words:
            continue
        if words[0] == "fault":
            d.fault(int(words[1], 0))
        elif words[0] == "mute":
            d.node.nmt.stop_heartbeat()
            d.say("muted")
        elif words[0] == "unmute":
            d.node.nmt.start_heartbeat(d.get(0x1017))
            d.say("unmuted")
        elif words[0] == "quit":
            break
    d.say("syncs=%d tpdos=%d position=%d" % (d.syncs, d.tpdos, d.get(0x6064)))
    d.node.nmt.stop_heartbeat()
    d.net.disconnect()


if __name__ == "__main__":
    main()

"""The bus redundancy object of ECSS-E-ST-50-15C, as Lely's CANopen stack implements it.

What was taken from where (read, not guessed):

* ECSS-E-ST-50-15C "CANbus extension protocol" (ESA, 1 May 2015; table of contents on
  ecss.nl / iteh.ai: 4.8 "Redundancy management and monitoring", 4.8.2 node monitoring by
  heartbeat, 4.8.3 bus redundancy) and LibreCube's SpaceCAN summary of it
  (wiki.librecube.org/SpaceCAN): every node sits on a nominal and a redundant line (bus A,
  bus B); "the master node defines the bus to be considered active by periodic transmission
  of heartbeat messages on the active bus. The slave nodes monitor the presence of the
  heartbeat message from the master to determine the active bus." A node either has one CAN
  controller and selects the line (selective bus access) or one controller per line
  (parallel bus access).
* lely-core, src/co/nmt_rdn.c and nmt_rdn.h (the "NMT redundancy manager", N7 Space 2021,
  developed under an ESA programme), and its unit tests (test/unit/test-nmt-rdn.cpp):
  the redundancy object (CO_NMT_RDN_REDUNDANCY_OBJ_IDX, 2000h by default and a build
  option) has four UNSIGNED8 sub-indices: 1 Bdefault (the default bus), 2 Ttoggle (the
  toggle time, in units of the master's consumer heartbeat time), 3 Ntoggle (the maximum
  number of toggles), 4 Ctoggle (the toggle counter). The redundancy master is the producer
  of the node's first consumer heartbeat entry (1016h sub 1, CO_NMT_RDN_MASTER_HB_IDX).
  The slave's rule (co_nmt_rdn_slave_missed_hb, co_nmt_rdn_bus_toggle_timer): when the
  master's heartbeat times out (1016h:1 time), a timer of (Ttoggle - 1) consumer times
  starts ("the first HB interval already passed"); when it fires the node switches to the
  other bus, increments Ctoggle and reports BUS_SWITCH; while Ctoggle < Ntoggle the timer is
  re-armed for Ttoggle consumer times, else the current bus becomes Bdefault, the timer
  stops and NO_MASTER is reported. Lely's master side sets the active bus for the whole
  network (co_nmt_set_active_bus); how it decides is left to the application.

Our drives already use 2000h (temperature), so the object sits at 2E00h; the index is a
build option in Lely too. Lines are numbered 0 (A, nominal) and 1 (B, redundant).
"""
from __future__ import annotations

REDUNDANCY = 0x2E00        # RECORD of UNSIGNED8
BDEFAULT = 1               # default line, 0 = A, 1 = B (the line the node listens on after a reset)
TTOGGLE = 2                # toggle time, in consumer heartbeat times of the master (1016h:1)
NTOGGLE = 3                # maximum number of toggles without hearing the master
CTOGGLE = 4                # toggle counter (the node counts; the master reads and resets it)

MASTER_CONSUMER_SUB = 1    # 1016h sub-index whose producer is the redundancy master

DEFAULTS = {BDEFAULT: 0, TTOGGLE: 1, NTOGGLE: 8, CTOGGLE: 0}
NAMES = {BDEFAULT: "Bdefault", TTOGGLE: "Ttoggle", NTOGGLE: "Ntoggle", CTOGGLE: "Ctoggle"}

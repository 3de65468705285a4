"""Worker process for :func:`hevsim.battery.fmu.simulate_fmu`: drives one FMU with FMPy.

Reads a JSON request on stdin (fmu path, step, inputs per step, output names), prints the
outputs as JSON and leaves with ``os._exit`` so that a crash in an FMU's teardown cannot
turn a finished run into a failure (running FMUs in a worker process contains such crashes).
"""

from __future__ import annotations

import json
import os
import sys
from collections import deque


def main() -> None:
    """Run the request read from stdin."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    messages: deque[str] = deque(maxlen=3)  # the last few

    def log(env: object, name: object, status: int, category: object, message: bytes) -> None:
        messages.append(message.decode(errors="replace"))

    callbacks = fmi2CallbackFunctions()  # the FMU's log messages, to report a failed step
    callbacks.logger = fmi2CallbackLoggerTYPE(log)
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    req = json.load(sys.stdin)
    md = read_model_description(req["fmu"])
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(
        guid=md.guid,
        unzipDirectory=extract(req["fmu"]),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="hevsim",
    )
    slave.instantiate(callbacks=callbacks, loggingOn=True)
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    if req["parameters"]:
        slave.setReal([vr[k] for k in req["parameters"]], list(req["parameters"].values()))
    if req.get("booleans"):
        slave.setBoolean([vr[k] for k in req["booleans"]], list(req["booleans"].values()))
    slave.exitInitializationMode()
    names = req["outputs"]
    outputs: dict[str, list[float]] = {k: [] for k in names}
    in_refs = [vr[k] for k in req["inputs"]]
    t, dt = 0.0, float(req["dt_s"])
    for row in zip(*req["inputs"].values(), strict=True):
        slave.setReal(in_refs, list(row))
        try:
            slave.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
        except FMICallException as exc:  # one line: the call, its status and the FMU's message
            sys.stderr.write(f"the step from t = {t:g} s: {exc} {' '.join(messages)}\n")
            sys.stderr.flush()
            os._exit(1)
        t += dt
        for k, v in zip(names, slave.getReal([vr[k] for k in names]), strict=True):
            outputs[k].append(v)
    slave.terminate()
    print(json.dumps(outputs), flush=True)
    os._exit(0)


if __name__ == "__main__":
    main()

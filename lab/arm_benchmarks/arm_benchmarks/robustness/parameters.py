"""Parameters of running nodes over the ROS parameter services, and the node conventions report:
descriptors, ranges, config-file coverage and run-time rejection of bad values."""

from __future__ import annotations

import yaml
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, ListParameters, SetParameters
from rclpy.parameter import Parameter

from arm_benchmarks.robustness.nodes import NODE_NAMES
from arm_ros.processes import NODES, config_file

BUILTIN_PARAMETERS = {"use_sim_time", "start_type_description_service"}


def _call(probe, srv_type, service: str, request, timeout_s: float = 20.0):
    client = probe.node.create_client(srv_type, service)
    try:
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise TimeoutError(f"service {service} not available")
        future = client.call_async(request)
        if not probe.wait_until(future.done, timeout_s):
            raise TimeoutError(f"no answer from {service}")
        return future.result()
    finally:
        probe.node.destroy_client(client)


def describe_parameters(probe, node_name: str) -> dict[str, dict]:
    """{name: {type, description, has_range, constraints, read_only}} of a running node."""
    names = list(_call(probe, ListParameters, f"/{node_name}/list_parameters", ListParameters.Request()).result.names)
    descriptors = _call(
        probe, DescribeParameters, f"/{node_name}/describe_parameters", DescribeParameters.Request(names=names)
    ).descriptors
    numeric = {ParameterType.PARAMETER_INTEGER: "integer", ParameterType.PARAMETER_DOUBLE: "double"}
    return {
        d.name: {
            "type": int(d.type),
            "numeric": int(d.type) in numeric,
            "description": d.description,
            "has_range": bool(len(d.integer_range) or len(d.floating_point_range)),
            "constraints": d.additional_constraints,
            "read_only": bool(d.read_only),
        }
        for d in descriptors
    }


def set_parameter(probe, node_name: str, name: str, value) -> tuple[bool, str]:
    """Set one parameter of a running node: (successful, reason)."""
    request = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
    result = _call(probe, SetParameters, f"/{node_name}/set_parameters", request).results[0]
    return bool(result.successful), result.reason


def config_keys(config_name: str, node_name: str) -> set[str]:
    """Parameter names (dotted) in config/<file> for node_name."""
    data = yaml.safe_load(config_file(config_name).read_text())[node_name]["ros__parameters"]

    def flatten(prefix, value):
        if isinstance(value, dict):
            for k, v in value.items():
                yield from flatten(f"{prefix}{k}.", v)
        else:
            yield prefix[:-1]

    return set(flatten("", data))


def convention_report(probe, key: str) -> dict:
    """Descriptors, ranges, config-file coverage and run-time rejection of bad values of one node."""
    node_name = NODE_NAMES[key]
    params = describe_parameters(probe, node_name)
    own = {n: p for n, p in params.items() if n not in BUILTIN_PARAMETERS}
    report = {
        "parameters": len(own),
        "without_description": sorted(n for n, p in own.items() if not p["description"]),
        "numeric_without_range": sorted(n for n, p in own.items() if p["numeric"] and not p["has_range"]),
    }
    if NODES[key][2]:
        keys = config_keys(NODES[key][2], node_name)
        report["in_config_not_declared"] = sorted(keys - set(own))
        report["declared_not_in_config"] = sorted(set(own) - keys)
    report["writable"] = sorted(n for n, p in own.items() if not p["read_only"])
    first = next(iter(sorted(own)), None)
    if first is not None:  # a read-only parameter refuses a new value, even one of its own type
        probe_value = {1: False, 2: 1, 3: 1.0, 4: "x"}.get(own[first]["type"], "x")
        report["set_refused"] = not set_parameter(probe, node_name, first, probe_value)[0]
    accepted = []
    for name, p in own.items():
        if p["read_only"]:
            continue
        if p["numeric"] and p["has_range"]:
            ok, _ = set_parameter(probe, node_name, name, 10**12 if p["type"] == 2 else 1e12)
            if ok:
                accepted.append(f"{name}=1e12")
        elif p["constraints"].startswith("one of:"):
            ok, _ = set_parameter(probe, node_name, name, "not-a-choice")
            if ok:
                accepted.append(f"{name}='not-a-choice'")
    report["bad_values_accepted_at_run_time"] = accepted
    return report

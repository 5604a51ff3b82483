"""Dump every parameter a node declares (name, type, value, description, ranges, read-only, constraints) as JSON.

For a refactor of parameter definitions: dump the node of the old and of the new source tree and compare the files
(they must be equal except where a description was corrected). The node is built in-process (no spin), so its
package is imported from the first matching entry of ``sys.path``: put the tree's ``src/<package>`` folders first::

    source /work/main/.venv/bin/activate && source install/setup.bash
    T=/path/to/tree/src; PYTHONPATH=$T/rfi_monitor:$T/gnss_common:$T/rfi_node_common:$PYTHONPATH \\
        python tools/dump_parameter_descriptors.py rfi_monitor.rfi_monitor_node RfiMonitorNode old.json
    diff old.json new.json
"""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path


def dump(module: str, class_name: str) -> dict[str, dict]:
    """name -> descriptor of every parameter the node declares (its own and rclpy's)."""
    import rclpy
    from rclpy.context import Context

    node_cls = getattr(importlib.import_module(module), class_name)
    context = Context()
    rclpy.init(context=context, args=[])
    try:
        node = node_cls(context=context)
        names = sorted(node._parameters)
        rows = {}
        for name, d in zip(names, node.describe_parameters(names), strict=True):
            p = node.get_parameter(name)
            rows[name] = {
                'value': repr(p.value), 'type': str(p.type_), 'description': d.description, 'read_only': d.read_only,
                'additional_constraints': d.additional_constraints, 'dynamic_typing': d.dynamic_typing,
                'float_range': [(r.from_value, r.to_value, r.step) for r in d.floating_point_range],
                'int_range': [(r.from_value, r.to_value, r.step) for r in d.integer_range]}
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    return rows


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    module, class_name, out = args
    rows = dump(module, class_name)
    Path(out).write_text(json.dumps(rows, indent=1, sort_keys=True) + '\n')
    package = importlib.import_module(module.split('.')[0])
    print(f'{len(rows)} parameters of {class_name} ({package.__file__}) -> {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

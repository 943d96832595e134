"""The Jazzy ``main`` of every node of the suite, written once."""

from __future__ import annotations

from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def run_node(factory: Callable[[], Node], name: str, args: list[str] | None = None) -> int:
    """init, spin until Ctrl-C or shutdown, then close, destroy and shut down.

    A configuration error (``ValueError`` or ``OSError`` such as ``FileExistsError`` from the
    constructor) is printed as ``name: message`` and gives exit code 1. A node with a ``close()``
    method gets it called before it is destroyed. A node that sets ``exit_code`` (and
    ``exit_reason``) ends with that code, the reason printed as ``name: reason``.
    """
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ValueError, OSError) as err:
        print(f"{name}: {err}", flush=True)
        return 1
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if callable(close):
                close()
            node.destroy_node()
        rclpy.try_shutdown()
    code = int(getattr(node, "exit_code", 0) or 0)
    if code:
        print(f"{name}: {getattr(node, 'exit_reason', '') or 'failed'}", flush=True)
    return code

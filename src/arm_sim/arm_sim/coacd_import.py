"""CoACD (convex decomposition), imported so that it cannot crash the ROS middleware loaded after it.

coacd 1.0.14's library links its own copy of libstdc++ and exports that copy's locale facet ids as
process-wide unique symbols. A C++ library loaded after it that builds a std::regex while it loads
(Fast DDS does, in IPLocator's static initialiser, when rclpy's extension is first imported) then
looks up the wrong facets and dies with SIGSEGV in std::codecvt (gdb backtrace; `import coacd;
import rclpy` crashes, `import rclpy; import coacd` does not). So rclpy's extension, when it is
installed, is loaded first; processes without ROS get CoACD alone.
"""


def import_coacd():
    """The coacd module, with rclpy's C extension (and Fast DDS) loaded before it where installed."""
    try:
        import rclpy.impl.implementation_singleton  # noqa: F401  (load order, see the module docstring)
    except ImportError:
        pass
    import coacd

    return coacd

"""Nav2-style managed nodes (``rclpy.lifecycle``): configure loads the parameters, the map's
planner and models and creates the node's topics; activate starts publishing and acting;
deactivate stops (local_refiner: zero velocity first); cleanup lets go of what configure made.
``nav2_lifecycle_manager`` or any client of the ``<node>/change_state`` service can drive them.

With ``autostart`` (the default) a node configures and activates itself at start-up, so
``ros2 run ecahd_ros global_planner`` just works, and a configuration that fails still ends the
node with one line and exit code 1 (``ecahd_ros.spin``). Without it the node waits,
unconfigured, for a lifecycle manager; a failed configure then answers the transition with
FAILURE and one error line naming the problem, and the node keeps running."""
from __future__ import annotations

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from ecahd_core.errors import EcahdError

SUCCESS, FAILURE = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE


class ManagedNode(LifecycleNode):
    """A lifecycle node whose subclass implements :meth:`configure` (raising EcahdError
    naming the problem) and :meth:`release` (undo it); :attr:`active` tells the callbacks
    whether to act."""

    def __init__(self, name: str, **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.active = False
        self._autostarting = False
        self._configure_error: str | None = None
        self._entities: list = []  # publishers, subscriptions, timers configure made

    def made(self, entity):
        """Keep ``entity`` (a publisher, subscription or timer) for :meth:`destroy_made`."""
        self._entities.append(entity)
        return entity

    def destroy_made(self) -> None:
        """Destroy what :meth:`made` kept (a release's first step)."""
        for entity in self._entities:
            kind = type(entity).__name__
            if kind == "LifecyclePublisher":
                self.destroy_lifecycle_publisher(entity)
            elif kind == "Publisher":
                self.destroy_publisher(entity)
            elif kind == "Subscription":
                self.destroy_subscription(entity)
            else:
                self.destroy_timer(entity)
        self._entities = []

    def start(self, autostart: bool) -> None:
        """Configure and activate now (``autostart``), raising EcahdError if configuring
        fails; else wait for a lifecycle manager."""
        if not autostart:
            self.get_logger().info("unconfigured: waiting for a lifecycle manager to configure "
                                   "and activate this node (autostart is false)")
            return
        self._autostarting = True
        try:
            if self.trigger_configure() != SUCCESS:
                raise EcahdError(self._configure_error or "configuration failed")
        finally:
            self._autostarting = False
        if self.trigger_activate() != SUCCESS:
            raise EcahdError("activation failed")

    # subclasses implement these two
    def configure(self) -> None:
        raise NotImplementedError

    def release(self) -> None:
        raise NotImplementedError

    # ------------------------------------------------------------------ lifecycle callbacks
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.configure()
        except EcahdError as exc:
            self._configure_error = str(exc)
            if not self._autostarting:  # autostart: spin_node says it, and exits
                self.get_logger().error(f"cannot configure: {exc}")
            self.release()
            return FAILURE
        return SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)  # the lifecycle publishers start publishing
        self.active = result == SUCCESS
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self.release()
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self.release()
        return SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self.release()
        return SUCCESS

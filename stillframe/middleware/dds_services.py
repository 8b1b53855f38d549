"""ROS services on the ``dds`` backend, on ``rmw_cyclonedds_cpp``'s wire convention.

Service ``/a/b`` of type ``pkg/srv/S``: requests on the DDS topic ``rq/a/bRequest`` of type
``pkg::srv::dds_::S_Request_``, replies on ``rr/a/bReply`` of type ``pkg::srv::dds_::S_Response_``,
reliable, keep last 10, volatile (rmw's services profile). Between the CDR encapsulation header
and the message's fields every request and reply carries Cyclone rmw's request header
(``cdds_request_header_t`` in its ``serdata.hpp``): the client's 64-bit id (rmw uses the
request writer's instance handle) and the request's sequence number (int64), in the sample's
byte order; a reply repeats both, and a client keeps only the replies with its own id. The
readers and writers carry ``typehash=RIHS01_…;`` and ``serviceid=…;`` or ``clientid=…;`` in
their USER_DATA as rmw_cyclonedds writes them; a client calls once one service's reader and
writer are both matched, and a service, like rmw's, waits up to 100 ms for the caller's reply
reader before answering.

Fast DDS (rmw_fastrtps) uses the same topic and type names but sends the request header as
RTPS inline QoS instead of in the payload, so the two do not talk (docs/middleware.md): a
request that is too short or does not decode is refused, counted and logged once.
"""

from __future__ import annotations

import functools
import itertools
import struct
import time
from collections.abc import Callable
from typing import Any

from cyclonedds.core import DDSException, ReadCondition, WaitSet
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader

from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.middleware import interface, lifecycle, names, param_messages
from stillframe.middleware.cyclone_raw import ANY_SAMPLES, take_raw, write_raw
from stillframe.middleware.dds_backend import DdsNode, dds_qos, delete, user_data_field
from stillframe.middleware.qos import QoSProfile

SERVICE_QOS = QoSProfile(depth=10)
#: How long a service waits for the caller's reply reader to be matched (rmw_cyclonedds: 100 ms).
REPLY_MATCH_WAIT_S = 0.1
HEADER_SIZE = 16
ENCAPSULATION_SIZE = 4
_ids = itertools.count(1)


def request_topic(service: str) -> str:
    """``/a/b`` -> ``rq/a/bRequest``."""
    return f"rq{service}Request"


def reply_topic(service: str) -> str:
    """``/a/b`` -> ``rr/a/bReply``."""
    return f"rr{service}Reply"


def _byte_order(cdr: bytes) -> str:
    return "<" if cdr[1] & 1 else ">"   # encapsulation 0x0001 / 0x0003: little-endian


def wrap(cdr: bytes, guid: int, seq: int) -> bytes:
    """A message's CDR with the request header inserted after the encapsulation."""
    header = struct.pack(_byte_order(cdr) + "Qq", guid, seq)
    return cdr[:ENCAPSULATION_SIZE] + header + cdr[ENCAPSULATION_SIZE:]


def unwrap(data: bytes) -> tuple[int, int, bytes]:
    """(client id, sequence number, message CDR) of a request or reply; InputError if short."""
    if len(data) < ENCAPSULATION_SIZE + HEADER_SIZE:
        raise InputError(f"{len(data)} bytes: too short for a request header")
    guid, seq = struct.unpack_from(_byte_order(data) + "Qq", data, ENCAPSULATION_SIZE)
    return guid, seq, data[:ENCAPSULATION_SIZE] + data[ENCAPSULATION_SIZE + HEADER_SIZE:]


def endpoint_id(participant_gid: bytes) -> str:
    """A new client/service id as rmw_cyclonedds writes it: the participant's GUID prefix and a
    big-endian counter, hex bytes joined by dots, the first one two digits wide."""
    data = participant_gid[:12] + next(_ids).to_bytes(4, "big")
    return f"{data[0]:02x}" + "".join(f".{b:x}" for b in data[1:])


class _Endpoints:
    """The reader and writer of one service or client."""

    def __init__(self, node: DdsNode, srv_type: str, service: str, role: str) -> None:
        self.service_name = service
        self.request_type, self.response_type = f"{srv_type}_Request", f"{srv_type}_Response"
        self.id = endpoint_id(node.context.gid)
        serving = role == "serviceid"
        read_type, write_type = ((self.request_type, self.response_type) if serving
                                 else (self.response_type, self.request_type))
        read_topic, write_topic = ((request_topic(service), reply_topic(service)) if serving
                                   else (reply_topic(service), request_topic(service)))
        context = node.context
        self.reader = DataReader(
            context.participant, context.topic(read_topic, read_type, request_header=True),
            dds_qos(SERVICE_QOS, self._user_data(read_type, role), writer=False),
        )
        self.writer = DataWriter(
            context.participant, context.topic(write_topic, write_type, request_header=True),
            dds_qos(SERVICE_QOS, self._user_data(write_type, role)),
        )
        self.condition = ReadCondition(self.reader, ANY_SAMPLES)
        messages.prepare(read_type)
        messages.prepare(write_type)

    def _user_data(self, ros_type: str, role: str) -> bytes:
        return f"typehash={messages.type_hash(ros_type)};{role}={self.id};".encode()

    def take(self) -> list[tuple[bytes, Any]]:
        return [(bytes(data), info) for data, info in take_raw(self.reader, 256)
                if info.valid_data]

    def destroy(self) -> None:
        delete(self.reader)
        delete(self.writer)


class DdsService(_Endpoints):
    """Answers requests with ``answer(request) -> response`` (``rosbags`` messages)."""

    def __init__(self, node: DdsNode, srv_type: str, service: str,
                 answer: Callable[[Any], Any]) -> None:
        super().__init__(node, srv_type, service, "serviceid")
        self.answer = answer
        self.logger = node.get_logger()
        self.rejected = 0

    def _reply_reader_matched(self, client_id: str) -> bool:
        return any(user_data_field(self.writer.get_matched_subscription_data(h).qos, "clientid")
                   == client_id for h in self.writer.get_matched_subscriptions())

    def _wait_for_caller(self, info: Any) -> None:
        """rmw_cyclonedds' wait: until the requesting client's reply reader is matched."""
        try:
            caller = self.reader.get_matched_publication_data(info.publication_handle)
        except DDSException:   # the caller is gone; the reply goes nowhere anyway
            return
        client_id = user_data_field(caller.qos, "clientid")
        deadline = time.monotonic() + REPLY_MATCH_WAIT_S
        while (client_id and not self._reply_reader_matched(client_id)
               and time.monotonic() < deadline):
            time.sleep(0.005)

    def take_and_answer(self) -> int:
        """Answer every waiting request; the number answered (undecodable ones are counted in
        ``rejected`` and logged once)."""
        answered = 0
        for data, info in self.take():
            try:
                guid, seq, cdr = unwrap(data)
                request = messages.deserialize(cdr, self.request_type)
            except Exception as exc:   # foreign bytes may fail to decode in any way
                self.rejected += 1
                self.logger.warning(
                    f"{self.service_name}: refused a request that does not decode as "
                    f"{self.request_type} after rmw_cyclonedds' request header ({exc}); "
                    "a client on another DDS vendor?", once=True)
                continue
            self._wait_for_caller(info)
            write_raw(self.writer, wrap(messages.serialize(self.answer(request)), guid, seq))
            answered += 1
        return answered


class DdsClient(_Endpoints):
    """Calls one service: :meth:`wait_for_service`, then :meth:`call`."""

    def __init__(self, node: DdsNode, srv_type: str, service: str) -> None:
        super().__init__(node, srv_type, service, "clientid")
        self.guid = self.writer.instance_handle & (2**64 - 1)
        self.seq = 0
        self.waitset = WaitSet(node.context.participant)
        self.waitset.attach(self.condition)

    def service_is_ready(self) -> bool:
        """One service's request reader and reply writer are both matched (rmw_cyclonedds'
        check). Unlike rmw_cyclonedds, a service whose matched readers carry no ``serviceid``
        (another rmw, such as Fast DDS) is never ready: such a server reads rmw_cyclonedds'
        in-payload request header as the request's fields, and a sequence length taken from
        the header's bytes can make it allocate and initialise millions of strings, stalling it
        for longer than any call waits (docs/middleware.md)."""
        readers = {user_data_field(self.writer.get_matched_subscription_data(h).qos, "serviceid")
                   for h in self.writer.get_matched_subscriptions()}
        writers = {user_data_field(self.reader.get_matched_publication_data(h).qos, "serviceid")
                   for h in self.reader.get_matched_publications()}
        return bool((readers & writers) - {""})

    def wait_for_service(self, timeout_sec: float) -> bool:
        deadline = time.monotonic() + timeout_sec
        while not self.service_is_ready():
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.02)
        return True

    def call(self, request: Any, timeout_sec: float, *,
             give_up: Callable[[], bool] | None = None) -> Any | None:
        """Send ``request`` and wait for its reply (None after ``timeout_sec``, or once
        ``give_up()`` holds, checked every :data:`.interface.GIVE_UP_CHECK_S`)."""
        self.seq += 1
        write_raw(self.writer, wrap(messages.serialize(request), self.guid, self.seq))
        deadline = time.monotonic() + timeout_sec
        while (remaining := deadline - time.monotonic()) > 0 and not (give_up and give_up()):
            self.waitset.wait(int(min(remaining, interface.GIVE_UP_CHECK_S) * 1e9))
            for data, _info in self.take():
                guid, seq, cdr = unwrap(data)
                if guid == self.guid and seq == self.seq:
                    return messages.deserialize(cdr, self.response_type)
        return None

    def destroy(self) -> None:
        delete(self.waitset)
        super().destroy()


class ServiceNode(DdsNode):
    """A :class:`.dds_backend.DdsNode` that also serves services, among them the standard
    parameter services ``~/list_parameters``, ``~/get_parameters``, ``~/set_parameters`` and
    ``~/describe_parameters`` of its parameters (rclpy serves the same)."""

    def __init__(self, name: str, namespace: str, args: list[str]) -> None:
        self._services: list[DdsService] = []
        self._clients: list[DdsClient] = []
        super().__init__(name, namespace, args)
        for suffix, (srv_type, answer) in param_messages.PARAMETER_SERVICES.items():
            self.create_service(srv_type, f"~/{suffix}", functools.partial(answer, self._params))

    def manage(self, on_transition: lifecycle.TransitionCallback) -> None:
        """Make this a managed node: rcl_lifecycle's state machine with ``on_transition`` as its
        callbacks, served on the ``lifecycle_msgs`` services (``~/get_state``,
        ``~/change_state``, ...) with ``~/transition_event`` published, as rclpy's
        ``LifecycleNode`` serves them."""
        events = self.create_publisher("lifecycle_msgs/msg/TransitionEvent",
                                       lifecycle.TRANSITION_EVENT, "default")
        self.lifecycle = lifecycle.StateMachine(
            on_transition, lambda t: events.publish(lifecycle.event_msg(t)))
        answers = lifecycle.answers(self.lifecycle, self.get_logger().warning)
        for name, srv in lifecycle.SERVICES.items():
            self.create_service(f"lifecycle_msgs/srv/{srv}", f"~/{name}", answers[name])

    def lifecycle_state(self) -> str:
        """The label of the managed node's state (``unconfigured``, ``active``, ...)."""
        return self.lifecycle.label

    def trigger(self, transition: str) -> str:
        """Run the node's own ``transition`` (a label; ``shutdown`` from any primary state);
        the outcome (:data:`.lifecycle.SUCCESS` ...), TransitionRefusedError if not available."""
        return self.lifecycle.change(label=transition)

    def resolve_service_name(self, service: str) -> str:
        return names.resolve_topic(service, self.get_namespace(), self.get_name())

    def create_service(self, srv_type: str, service: str,
                       callback: Callable[[Any], Any]) -> DdsService:
        """Serve ``service`` with ``callback(request) -> response`` while the node spins."""
        served = DdsService(self, srv_type, self.resolve_service_name(service), callback)
        self._services.append(served)
        self.attach(served.condition, served.take_and_answer)
        self.context.publish_graph()
        return served

    def create_client(self, srv_type: str, service: str) -> DdsClient:
        client = DdsClient(self, srv_type, self.resolve_service_name(service))
        self._clients.append(client)
        self.context.publish_graph()
        return client

    def call_service(self, srv_type: str, service: str, request: Any,
                     timeout_sec: float, *, give_up: Callable[[], bool] | None = None,
                     ) -> Any | None:
        """Wait for ``service`` and call it once (a client made on first use); the response,
        or None if the service did not appear or answer within ``timeout_sec``, or once
        ``give_up()`` holds while the reply is awaited."""
        name = self.resolve_service_name(service)
        client = next((c for c in self._clients if c.service_name == name), None)
        client = client or self.create_client(srv_type, name)
        deadline = time.monotonic() + timeout_sec
        if not client.wait_for_service(timeout_sec):
            return None
        return client.call(request, max(deadline - time.monotonic(), 0.0), give_up=give_up)

    def reader_gids(self) -> list[bytes]:
        return [*super().reader_gids(), *(s.reader.guid.bytes for s in self._endpoints())]

    def writer_gids(self) -> list[bytes]:
        return [*super().writer_gids(), *(s.writer.guid.bytes for s in self._endpoints())]

    def _endpoints(self) -> list[_Endpoints]:
        return [*self._services, *self._clients]

    def destroy_node(self) -> None:
        for served in self._services:
            self.detach(served.condition)
        for endpoint in self._endpoints():
            endpoint.destroy()
        self._services.clear()
        self._clients.clear()
        super().destroy_node()

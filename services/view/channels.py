"""Foxglove channels opened on first use, in one foxglove Context (a WebSocket server or an MCAP writer).

Each topic gets the SDK's typed channel for the message's schema (GridChannel for a Grid, …) or,
for a JsonMessage, a JSON channel with its JSON Schema. The latest message of every topic is kept, so a viewer that
subscribes late (after the map was published once) can be sent it again.
"""
from __future__ import annotations

import json
import threading
from typing import Any

import foxglove
import foxglove.channels

from .convert import JsonMessage


class ChannelSet:
    def __init__(self, context: foxglove.Context):
        self.context = context
        self._channels: dict[str, Any] = {}
        self._latest: dict[str, Any] = {}
        # the server's subscribe callback (resend) runs on another thread than log()
        self._lock = threading.Lock()

    def _channel(self, topic: str, message: Any):
        channel = self._channels.get(topic)
        if channel is None:
            if isinstance(message, JsonMessage):
                schema = foxglove.Schema(name=message.schema_name, encoding="jsonschema",
                                         data=json.dumps(message.schema).encode())
                channel = foxglove.Channel(topic, schema=schema, message_encoding="json", context=self.context)
            else:
                channel_class = getattr(foxglove.channels, f"{type(message).__name__}Channel")
                channel = channel_class(topic, context=self.context)
            self._channels[topic] = channel
        return channel

    def log(self, topic: str, message: Any, log_time_ns: int | None = None) -> None:
        with self._lock:
            channel = self._channel(topic, message)
            self._latest[topic] = message
        self._log(channel, message, log_time_ns)

    @staticmethod
    def _log(channel, message: Any, log_time_ns: int | None = None) -> None:
        channel.log(message.value if isinstance(message, JsonMessage) else message, log_time=log_time_ns)

    def resend_latest(self, topic: str) -> None:
        """Log the newest message of a topic again (for a viewer that just subscribed to it)."""
        with self._lock:
            channel, message = self._channels.get(topic), self._latest.get(topic)
        if channel is not None:
            self._log(channel, message)

    @property
    def topics(self) -> list[str]:
        with self._lock:
            return sorted(self._channels)

    def close(self) -> None:
        with self._lock:
            for channel in self._channels.values():
                channel.close()
            self._channels.clear()

"""The schedule service over Eclipse Zenoh: key expressions (`keys`), request validation
(`protocol`), the computation behind a reply (`engine`, the per-pose chain on a trained model),
the server (`server`), session configuration (`session`) and the cell's client (`client`).
TLS / mTLS / ACL examples are in `config/`."""

from service.zenoh_service.client import ScheduleClient, ServiceError
from service.zenoh_service.engine import ScheduleEngine
from service.zenoh_service.protocol import RequestError
from service.zenoh_service.server import ScheduleService, ServiceSettings
from service.zenoh_service.session import zenoh_config

__all__ = ["RequestError", "ScheduleClient", "ScheduleEngine", "ScheduleService", "ServiceError", "ServiceSettings", "zenoh_config"]

# Copyright 2026 The mv3dpose_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Forward Python ``logging`` records of the core to a node's ROS logger."""

import logging
from typing import Any


class RosLogHandler(logging.Handler):
    """A ``logging`` handler that writes each record to ``node.get_logger()``."""

    def __init__(self, node: Any) -> None:
        super().__init__(logging.INFO)
        self._node = node

    def emit(self, record: logging.LogRecord) -> None:
        """Log ``record`` at its level (ERROR, WARNING, else INFO), prefixed with its name."""
        logger = self._node.get_logger()
        text = f'{record.name}: {record.getMessage()}'
        if record.levelno >= logging.ERROR:
            logger.error(text)
        elif record.levelno >= logging.WARNING:
            logger.warning(text)
        else:
            logger.info(text)

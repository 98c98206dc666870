# SPDX-License-Identifier: Apache-2.0
"""World descriptions: world YAML, BARN JSON, map files, and where the package keeps them."""

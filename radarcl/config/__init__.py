"""How a map is made, in one place: the stages' configurations in bins (``stage_config``), the
keys of a map configuration in metres (``keys``), sensor profiles (``sensors``), their
resolution into a configuration (``mapconfig``), TOML files (``tomlfile``) and named
configurations (``presets``)."""

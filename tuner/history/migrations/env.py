"""Alembic's environment for the history database: always run programmatically (tuner.history.store.upgrade), on
the connection it is handed, with this package's own version table."""

from alembic import context

from tuner.history.schema import VERSION_TABLE, metadata

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=metadata, version_table=VERSION_TABLE,
                  render_as_batch=connection.dialect.name == "sqlite")
with context.begin_transaction():
    context.run_migrations()

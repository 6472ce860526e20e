"""Reading and writing files: scene folders, format adapters, camera files, atomic writers."""

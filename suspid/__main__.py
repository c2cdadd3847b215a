from suspid.cli import main

raise SystemExit(main())

from beyond_self.cli import main

raise SystemExit(main())

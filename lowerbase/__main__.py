from lowerbase.cli import main

raise SystemExit(main())

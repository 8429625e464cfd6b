from lobeview.app.cli import main

raise SystemExit(main())

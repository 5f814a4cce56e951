from radarcl.cli import main

raise SystemExit(main())

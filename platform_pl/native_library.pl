:- module(native_library,
          [ native_library_load/2,      % +Name, -Loaded
            native_library_file/2       % +Name, -File
          ]).

/** <module> Loading one of the platform's foreign libraries

The platform's foreign libraries are C sources, native/Name.c. Each is
loaded from the first of:

  1. native/Name.so beside its source, when it is not older than the
     source: what `scripts/setup.sh` (`native/build.sh`) builds in a
     checkout;
  2. a per-user cache, Cache/SWI-VERSION-ARCH/HASH/Name.so, where HASH
     is that of the source: built there with `swipl-ld` on first use
     (about 0.25 s a library), so an installed wheel, which ships the
     sources only, never writes into site-packages and a library built
     for one SWI-Prolog is never loaded by another. Cache is
     `$DFRL_NATIVE_CACHE`, else `$XDG_CACHE_HOME/dfrl/native`, else
     `~/.cache/dfrl/native`.

A build writes a temporary file and renames it, so processes starting
together never load half a library. Each module that has a foreign
library falls back to plain Prolog where it cannot be built or loaded,
and says so once with a warning naming the library and the reason.
*/

:- use_module(library(process), [process_create/3, process_wait/2]).
:- use_module(library(readutil), [read_stream_to_codes/2, read_file_to_codes/3]).

:- dynamic native_dir/1.

:- prolog_load_context(directory, Dir),
   directory_file_path(Dir, native, Native),
   assertz(native_dir(Native)).

:- multifile prolog:message//1.

prolog:message(native_library(Name, Why)) -->
    [ 'dfrl: the foreign library ~w is not used (~w); the platform runs its Prolog version, \c
       slower'-[Name, Why] ].

%!  native_library_load(+Name, -Loaded) is det.
%
%   Load the foreign library Name into the process, building it on
%   first use (see the module doc): Loaded is `true`, or `false` with a
%   warning if it cannot be built or does not load.

native_library_load(Name, Loaded) :-
    catch(native_library_file(Name, Lib), E, (why(E, Why), true)),
    (   var(Why)
    ->  catch(load_foreign_library(Lib), E2, (why(E2, Why), true))
    ;   true
    ),
    (   var(Why)
    ->  Loaded = true
    ;   print_message(warning, native_library(Name, Why)),
        Loaded = false
    ).

why(E, Why) :-
    (   catch(( '$messages':translate_message(E, Lines, []),
                print_message_lines(atom(Text), '', Lines) ), _, fail)
    ->  normalize_space(atom(Why), Text)
    ;   format(atom(Why), '~q', [E])
    ).

%!  native_library_file(+Name, -File) is det.
%
%   File is the built library for native/Name.c: the checkout's build
%   when it is current, else the per-user cache's, built now if
%   missing. Raises an error when the source is missing or the build
%   fails (the compiler's output in the error).

native_library_file(Name, File) :-
    native_dir(Dir),
    directory_file_path(Dir, Name, Base),
    file_name_extension(Base, c, Source),
    file_name_extension(Base, so, Beside),
    (   exists_file(Source)
    ->  true
    ;   existence_error(native_source, Source)
    ),
    (   exists_file(Beside),
        time_file(Beside, Built), time_file(Source, Written),
        Built >= Written
    ->  File = Beside
    ;   cached_file(Name, Source, File),
        (   exists_file(File)
        ->  true
        ;   build(Source, File)
        )
    ).

cached_file(Name, Source, File) :-
    cache_dir(Cache),
    current_prolog_flag(version, Version),
    current_prolog_flag(arch, Arch),
    format(atom(Sub), '~w-~w', [Version, Arch]),
    read_file_to_codes(Source, Codes, []),
    variant_sha1(Codes, Hash),
    sub_atom(Hash, 0, 16, _, Short),
    file_name_extension(Name, so, Leaf),
    atomic_list_concat([Cache, Sub, Short, Leaf], /, File).

cache_dir(Dir) :-
    (   getenv('DFRL_NATIVE_CACHE', Dir), Dir \== ''
    ->  true
    ;   getenv('XDG_CACHE_HOME', Xdg), Xdg \== ''
    ->  directory_file_path(Xdg, 'dfrl/native', Dir)
    ;   getenv('HOME', Home), Home \== ''
    ->  directory_file_path(Home, '.cache/dfrl/native', Dir)
    ;   existence_error(environment_variable, 'HOME')
    ).

%   build(+Source, +File): compile with swipl-ld into a temporary file
%   beside File, then rename it into place.

build(Source, File) :-
    file_directory_name(File, Folder),
    make_directory_path(Folder),
    current_prolog_flag(pid, Pid),
    format(atom(Tmp), '~w.~w.tmp', [File, Pid]),
    catch(process_create(path('swipl-ld'),
                         ['-shared', '-O2', '-o', Tmp, Source],
                         [ stdout(null), stderr(pipe(Err)), process(Proc) ]),
          E, (why(E, Why), throw(error(native_build(Source, Why), _)))),
    read_stream_to_codes(Err, Output),
    close(Err),
    process_wait(Proc, Status),
    (   Status == exit(0), exists_file(Tmp)
    ->  rename_file(Tmp, File)
    ;   catch(delete_file(Tmp), _, true),
        format(atom(Why), 'swipl-ld ~w: ~s', [Status, Output]),
        throw(error(native_build(Source, Why), _))
    ).

:- multifile prolog:error_message//1.

prolog:error_message(native_build(Source, Why)) -->
    [ 'cannot build ~w: ~w'-[Source, Why] ].

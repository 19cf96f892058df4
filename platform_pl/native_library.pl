:- module(native_library,
          [ native_library_load/2       % +Name, -Loaded
          ]).

/** <module> Loading one of the platform's foreign libraries

The platform's foreign libraries are native/Name.c, built into
native/Name.so by `scripts/setup.sh` (`native/build.sh`). Each module
that has one falls back to plain Prolog where it is not built.
*/

:- dynamic native_dir/1.

:- prolog_load_context(directory, Dir),
   directory_file_path(Dir, native, Native),
   assertz(native_dir(Native)).

%!  native_library_load(+Name, -Loaded) is det.
%
%   Load native/Name.so into the process: Loaded is `true`, or `false`
%   if it is not built or does not load (e.g. built for another
%   SWI-Prolog).

native_library_load(Name, Loaded) :-
    native_dir(Dir),
    directory_file_path(Dir, Name, Base),
    file_name_extension(Base, so, Lib),
    (   exists_file(Lib),
        catch(load_foreign_library(Lib), _, fail)
    ->  Loaded = true
    ;   Loaded = false
    ).

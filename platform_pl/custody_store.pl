:- module(custody_store,
          [ store_write/2,              % +File, +Term
            store_read/2,               % +File, -Term
            store_delete/1,             % +File
            store_terms/2,              % +Dir, -Pairs
            store_key_file/4,           % +Dir, +Key, +Ext, -File
            store_make_dirs/1           % +Dir
          ]).
:- autoload(library(process), [process_create/3, process_wait/2]).
:- autoload(library(filesex), [directory_file_path/3, make_directory_path/1]).
:- autoload(library(error), [must_be/2]).
:- autoload(library(lists), [member/2]).
:- autoload(library(apply), [include/3]).

/** <module> Durable terms in files: write to a temporary name, fsync, rename

The custody of agents (custody.pl) keeps its decisions and the agents a
node holds as one term per file. A file is replaced atomically:

  1. the term is written to `File.tmp` (canonical text, UTF-8),
  2. `File.tmp` is fsync'ed,
  3. it is renamed to File (atomic on POSIX file systems),
  4. the directory is fsync'ed, so the rename itself survives a crash.

A reader therefore sees the old term or the new one, never a mixture,
after a kill -9 and after a power cut. SWI-Prolog has no fsync/1, so
steps 2 and 4 run coreutils `sync FILE`, which calls fsync(2) on FILE
(about 4 ms each here). Left-over `.tmp` files (a write interrupted
before its rename) are ignored by store_terms/2 and deleted.

Terms are read back with read_term/3; a file that does not hold one
term is reported (print_message/2) and skipped, never called.
*/

%!  store_make_dirs(+Dir) is det.
%
%   Create Dir and its parents if needed.

store_make_dirs(Dir) :-
    must_be(atom, Dir),
    make_directory_path(Dir).

%!  store_key_file(+Dir, +Key, +Ext, -File) is det.
%
%   File is the file in Dir that holds the term for Key (any ground
%   term): its name is the SHA-1 of Key, so keys need not be file names.

store_key_file(Dir, Key, Ext, File) :-
    variant_sha1(Key, Hash),
    file_name_extension(Hash, Ext, Base),
    directory_file_path(Dir, Base, File).

%!  store_write(+File, +Term) is det.
%
%   Replace the content of File by Term, atomically and durably.
%
%   @error io_error/permission_error from the file system, or
%   `process_error(sync, Status)` if fsync failed.

store_write(File, Term) :-
    atom_concat(File, '.tmp', Tmp),
    setup_call_cleanup(
        open(Tmp, write, Out, [encoding(utf8)]),
        format(Out, '~k.~n', [Term]),
        close(Out)),
    fsync(Tmp),
    rename_file(Tmp, File),
    file_directory_name(File, Dir),
    fsync(Dir).

fsync(Path) :-
    process_create(path(sync), [file(Path)], [process(Pid)]),
    process_wait(Pid, Status),
    (   Status == exit(0)
    ->  true
    ;   throw(error(process_error(sync, Status), context(store_write/2, Path)))
    ).

%!  store_read(+File, -Term) is semidet.
%
%   Term is the term in File; fails if File does not exist.

store_read(File, Term) :-
    exists_file(File),
    setup_call_cleanup(
        open(File, read, In, [encoding(utf8)]),
        read_term(In, Term, [syntax_errors(error)]),
        close(In)),
    Term \== end_of_file.

%!  store_delete(+File) is det.
%
%   Delete File if it exists. The unlink is not fsync'ed: every reader
%   of a store tolerates a file that comes back after a crash (see the
%   recovery rules in custody.pl).

store_delete(File) :-
    (   exists_file(File)
    ->  delete_file(File)
    ;   true
    ).

%!  store_terms(+Dir, -Pairs) is det.
%
%   Pairs is a list File-Term of every complete file in Dir. Temporary
%   files of interrupted writes are deleted; unreadable files are
%   reported and skipped.

store_terms(Dir, Pairs) :-
    (   exists_directory(Dir)
    ->  directory_files(Dir, Names0),
        include([N]>>(N \== '.', N \== '..'), Names0, Names),
        findall(File-Term,
                ( member(Name, Names),
                  directory_file_path(Dir, Name, File),
                  readable_term(File, Term)
                ),
                Pairs)
    ;   Pairs = []
    ).

readable_term(File, Term) :-
    (   file_name_extension(_, tmp, File)
    ->  catch(delete_file(File), _, true),
        fail
    ;   catch(store_read(File, Term), E,
              ( print_message(warning, E), fail ))
    ).

:- module(custody_store,
          [ store_write/2,              % +File, +Term
            store_read/2,               % +File, -Term
            store_delete/1,             % +File
            store_terms/2,              % +Dir, -Pairs
            store_key_file/4,           % +Dir, +Key, +Ext, -File
            store_make_dirs/1           % +Dir
          ]).
:- autoload(library(process),
            [process_create/3, process_wait/2, process_wait/3, process_kill/1]).
:- autoload(library(readutil), [read_line_to_string/2]).
:- autoload(library(filesex), [directory_file_path/3, make_directory_path/1, chmod/2]).
:- autoload(library(error), [must_be/2]).
:- autoload(library(lists), [member/2]).
:- autoload(library(apply), [include/3]).
:- autoload(library(crypto), [crypto_data_hash/3]).

/** <module> Durable terms in files: write to a temporary name, fsync, rename

The custody of agents (custody.pl) keeps its decisions and the agents a
node holds as one term per file. A file is replaced atomically:

  1. the term is written to `File.tmp` (binary, see below),
  2. `File.tmp` is fsync'ed,
  3. it is renamed to File (atomic on POSIX file systems),
  4. the directory is fsync'ed, so the rename itself survives a crash.

A reader therefore sees the old term or the new one, never a mixture,
after a kill -9 and after a power cut. SWI-Prolog has no fsync/1: steps
2 and 4 ask one long-lived helper process, started on first use, to
fsync(2) the file (a perl one-liner: perl-base is part of every Debian
system; about 0.1 ms a call). Only that file is flushed, never the
whole system. Where the helper cannot run (no perl, a path with a
newline, the helper died), coreutils `sync FILE` is run instead, which
calls fsync(2) on FILE too (about 3 ms a call: a process each time).
Left-over `.tmp` files (a write interrupted before its rename) are
ignored by store_terms/2 and deleted.

A file holds the term in SWI-Prolog's fast serialization
(fast_term_serialized/2), after a one-line text header:

    dfrl_store(1, Length, SHA1).\n

Length is the number of bytes that follow and SHA1 their SHA-1 (hex).
Writing a large agent record this way costs a fraction of writing it as
canonical text (100,000 floats: about 20 ms instead of about 90), and
reading it back at recovery likewise. The fast-term decoder trusts its
input (garbage can crash the process), so the bytes are decoded only
when their length and SHA-1 match the header, and the term must be
acyclic and without attributed variables. A file without the header
(written by an older version: one canonical text term) is read with
read_term/3. A file that does not hold one term is reported
(print_message/2) and skipped, never called.
*/

%!  store_make_dirs(+Dir) is det.
%
%   Create Dir and its parents if needed; Dir itself is made readable by
%   its owner only (mode 700): the records in it hold agents' tokens.

store_make_dirs(Dir) :-
    must_be(atom, Dir),
    make_directory_path(Dir),
    chmod(Dir, 0o700).

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
    fast_term_serialized(Term, Bytes),
    string_length(Bytes, Len),
    crypto_data_hash(Bytes, Hash, [algorithm(sha1), encoding(octet)]),
    format(string(Header), "dfrl_store(1, ~d, ~q).~n", [Len, Hash]),
    atom_concat(File, '.tmp', Tmp),
    setup_call_cleanup(
        open(Tmp, write, Out, [type(binary)]),
        ( chmod(Tmp, 0o600),            % before the term (tokens) is in it
          set_stream(Out, record_position(false)),
          write(Out, Header),
          write(Out, Bytes) ),
        close(Out)),
    fsync(Tmp),
    rename_file(Tmp, File),
    file_directory_name(File, Dir),
    fsync(Dir).

fsync(Path) :-
    (   \+ sub_atom(Path, _, _, _, '\n'),
        with_mutex(dfrl_fsync, helper_fsync(Path, Answer))
    ->  (   Answer == "ok"
        ->  true
        ;   throw(error(io_error(fsync, Path), context(store_write/2, Answer)))
        )
    ;   sync_process(Path)
    ).

sync_process(Path) :-
    process_create(path(sync), [file(Path)], [process(Pid)]),
    process_wait(Pid, Status),
    (   Status == exit(0)
    ->  true
    ;   throw(error(process_error(sync, Status), context(store_write/2, Path)))
    ).

%   The fsync helper: reads one path a line, fsyncs it (a directory too)
%   and answers "ok" or "error: Reason". It ends when its input closes
%   (this process exits or stops it). fsync_helper_/3 holds its pipes
%   and process; a helper that cannot be started, or that dies, is not
%   started again (fsync/1 falls back to sync_process/1).

:- dynamic
    fsync_helper_/3,            % ToHelper, FromHelper, Pid
    fsync_helper_failed_/0.

fsync_helper_script(
"use IO::Handle; $| = 1;
 while (my $p = <STDIN>) {
   chomp $p;
   if (open(my $f, '<', $p)) {
     if ($f->sync) { print \"ok\\n\" } else { print \"error: $!\\n\" }
     close($f);
   } else { print \"error: $!\\n\" }
 }").

helper_fsync(Path, Answer) :-
    fsync_helper(To, From),
    catch(( format(To, "~w~n", [Path]),
            flush_output(To),
            read_line_to_string(From, Answer0)
          ),
          _, Answer0 = end_of_file),
    (   string(Answer0)
    ->  Answer = Answer0
    ;   helper_died,
        fail
    ).

fsync_helper(To, From) :-
    (   fsync_helper_(To0, From0, _)
    ->  To = To0,
        From = From0
    ;   \+ fsync_helper_failed_,
        fsync_helper_script(Script),
        catch(process_create(path(perl), ['-e', Script],
                             [ stdin(pipe(To)), stdout(pipe(From)),
                               stderr(null), process(Pid) ]),
              _, fail)
    ->  set_stream(To, encoding(utf8)),
        set_stream(From, encoding(utf8)),
        assertz(fsync_helper_(To, From, Pid))
    ;   ( fsync_helper_failed_ -> true ; assertz(fsync_helper_failed_) ),
        fail
    ).

helper_died :-
    (   retract(fsync_helper_(To, From, Pid))
    ->  catch(close(To, [force(true)]), _, true),
        catch(close(From, [force(true)]), _, true),
        catch(process_kill(Pid), _, true),
        catch(process_wait(Pid, _, [timeout(1)]), _, true)
    ;   true
    ),
    ( fsync_helper_failed_ -> true ; assertz(fsync_helper_failed_) ).

%!  store_read(+File, -Term) is semidet.
%
%   Term is the term in File; fails if File does not exist.

store_read(File, Term) :-
    exists_file(File),
    setup_call_cleanup(
        open(File, read, In, [type(binary)]),
        read_stored(In, File, Term),
        close(In)),
    Term \== end_of_file.

%   A file starts with its header (the binary format) or is one text
%   term (older stores). The header is read as a term of at most one
%   line; the bytes are decoded only once they are what it says.
read_stored(In, File, Term) :-
    peek_string(In, 11, Start),
    (   Start == "dfrl_store("
    ->  read_line_to_string(In, Line),
        catch(term_string(Header, Line), _, corrupt(File, header)),
        (   Header = dfrl_store(1, Len, Hash),
            integer(Len), Len >= 0,
            atom(Hash)
        ->  true
        ;   corrupt(File, header)
        ),
        read_string(In, Len, Bytes),
        string_length(Bytes, Got),
        (   Got =:= Len
        ->  true
        ;   corrupt(File, truncated)
        ),
        crypto_data_hash(Bytes, Hash1, [algorithm(sha1), encoding(octet)]),
        (   Hash1 == Hash
        ->  true
        ;   corrupt(File, checksum)
        ),
        fast_term_serialized(Term, Bytes),
        (   acyclic_term(Term),
            \+ term_attvars(Term, [_|_])
        ->  true
        ;   corrupt(File, term)
        )
    ;   set_stream(In, encoding(utf8)),     % an older store: one text term
        read_term(In, Term, [syntax_errors(error)])
    ).

corrupt(File, What) :-
    throw(error(io_error(read, File), context(store_read/2, corrupt(What)))).

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

:- module(node_id,
          [ node_id_new/1,              % -Id
            node_id_stored/2            % +Dir, -Id
          ]).
:- autoload(library(crypto), [crypto_n_random_bytes/2]).
:- autoload(library(readutil), [read_file_to_string/3]).
:- autoload(library(filesex), [make_directory_path/1, directory_file_path/3]).
:- autoload(library(lists), [member/2]).
:- autoload(library(apply), [maplist/3]).

/** <module> Node ids: 32 hex digits from the crypto random generator

A node's id is what "is this address me?" compares (see node_is_self/2
in node.pl); the same generator makes the nonces of the hello, from
which token proofs are made.
*/

%!  node_id_new(-Id) is det.
%
%   Id is a new atom of 32 lower-case hex digits (16 bytes of
%   crypto_n_random_bytes/2).

node_id_new(Id) :-
    crypto_n_random_bytes(16, Bytes),
    maplist([B, H]>>format(atom(H), '~|~`0t~16r~2+', [B]), Bytes, Hs),
    atomic_list_concat(Hs, Id).

%!  node_id_stored(+Dir, -Id) is det.
%
%   Id is the one kept in Dir/node_id, made (Dir too) and written once
%   (temporary file, then rename) if there is none, so that a node
%   restarted on the same store keeps its id.
%
%   @error domain_error(node_id, Text) if the file holds something else.

node_id_stored(Dir, Id) :-
    make_directory_path(Dir),
    directory_file_path(Dir, node_id, File),
    (   exists_file(File)
    ->  read_file_to_string(File, Text0, []),
        split_string(Text0, "", " \t\r\n", [Text]),
        (   string_length(Text, 32),
            string_codes(Text, Cs),
            forall(member(C, Cs), code_type(C, xdigit(_)))
        ->  atom_string(Id, Text)
        ;   throw(error(domain_error(node_id, Text), context(_, File)))
        )
    ;   node_id_new(Id),
        atom_concat(File, '.tmp', Tmp),
        setup_call_cleanup(open(Tmp, write, Out),
                           format(Out, "~w~n", [Id]),
                           close(Out)),
        rename_file(Tmp, File)
    ).

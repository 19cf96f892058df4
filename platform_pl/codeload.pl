:- module(codeload,
          [ load_program/1,             % +File
            load_program_at/3,          % +Address, +File, +Options
            load_program_text/4         % +Address, +Id, +Text, +Options
          ]).
:- use_module(node, [current_node/1, node_property/2, ctx_node/2,
                     ctx_authenticated/1]).
:- use_module(platform_errors, [message_text/2]).
:- use_module(code_safety, [check_program_text/2, code_trusted/1, forget_checked_code/0]).
:- use_module(transport).
:- autoload(library(error), [must_be/2]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(readutil), [read_file_to_string/3]).

/** <module> Loading agent programs into running nodes

A node can load a program (handlers, helper predicates, aggregation
methods) while it runs: from a local file, or sent by a peer that proves
one of the node's tokens. The program is loaded into `user`, where new
agents find their handlers. Errors and warnings raised while loading are
collected and returned to the sender.

A program sent by a peer is checked as a whole before any of it is
loaded (code_safety:check_program_text/2: every clause and directive),
unless the peer is trusted by name (node option trusted_peers(Names));
a refused program loads nothing and the sender gets the error. Locally
loaded programs (load_program/1, consult/1) are trusted.
*/

:- multifile node:platform_request/4.
:- multifile user:message_hook/3.
:- dynamic user:message_hook/3.

:- thread_local collecting/0, collected/1.

%!  load_program(+File) is det.
%
%   Load File into `user` on this process (and so into every node it
%   runs). Loading again replaces the file's previous definitions.

load_program(File) :-
    must_be(atomic, File),
    load_files(user:File, [if(true)]),
    forget_checked_code.

%!  load_program_at(+Address, +File, +Options) is det.
%
%   Send the text of File to the platform at Address, which loads it
%   into its `user` module without a restart. Options: tokens(List), the
%   tokens to prove (default the current node's), and the timeouts of
%   transport_open/3.
%
%   @error permission_error(load, platform, Address) if no token fits.
%   @error permission_error(install, code, Culprit) if the sandbox there
%   refused the program (nothing of it was loaded).
%   @error load_errors(Messages) if the program had errors there.

load_program_at(Address, File, Options) :-
    read_file_to_string(File, Text, []),
    file_base_name(File, Base),
    load_program_text(Address, Base, Text, Options).

%!  load_program_text(+Address, +Id, +Text, +Options) is det.
%
%   Like load_program_at/3 for program Text, known there as Id.

load_program_text(Address0, Id, Text, Options) :-
    must_be(atomic, Id),
    must_be(string, Text),
    address_normalize(Address0, Address),
    tokens(Options, Tokens),
    transport_request(Address, load_code(Id, Text), _,
                      [tokens(Tokens), action(load)|Options]).

tokens(Options, Tokens) :-
    (   option(tokens(Tokens), Options)
    ->  true
    ;   catch(current_node(Node), _, fail),
        node_property(Node, tokens(Tokens))
    ->  true
    ;   Tokens = []
    ).

load_text(Id, Text) :-
    format(atom(SourceId), 'dfrl_program://~w', [Id]),
    setup_call_cleanup(
        ( open_string(Text, In), assertz(collecting) ),
        load_files(user:SourceId, [stream(In), if(true)]),
        ( close(In), retractall(collecting) )),
    forget_checked_code,
    findall(M, retract(collected(M)), Errors),
    (   Errors == []
    ->  true
    ;   throw(error(load_errors(Errors), _))
    ).

%   syntax_error_at(+Id, +Text, +What, +Where)
%
%   The sandbox's reader refused Text with syntax_error(What): throw it
%   again as load_errors(["Id:Line:Column: Syntax error: ..."]), the
%   place found by reading Text term by term (a context of a remote
%   error is replaced by the peer's address, so the place travels in the
%   formal, as the messages of other load errors do). If no term of Text
%   fails to read on its own, the error is thrown as it came.

syntax_error_at(Id, Text, What, Where) :-
    (   first_syntax_error(Text, Line, LinePos, What1)
    ->  message_text(error(syntax_error(What1), _), Message),
        format(string(Located), "~w:~d:~d: ~w", [Id, Line, LinePos, Message]),
        throw(error(load_errors([Located]), _))
    ;   throw(error(syntax_error(What), Where))
    ).

first_syntax_error(Text, Line, LinePos, What) :-
    setup_call_cleanup(
        open_string(Text, In),
        catch(( repeat,
                read_term(In, Term, [module(user), syntax_errors(error)]),
                Term == end_of_file,
                !,
                fail
              ),
              error(syntax_error(What), stream(_, Line, LinePos, _)),
              true),
        close(In)).

user:message_hook(Term, error, _Lines) :-
    collecting,
    message_text(Term, Text),
    assertz(collected(Text)),
    fail.

node:platform_request(load_code(Id, Text), Ctx, Reply, true) :-
    ctx_node(Ctx, Node),
    (   ctx_authenticated(Ctx)
    ->  must_be(atomic, Id),
        must_be(string, Text),
        (   code_trusted(Ctx)
        ->  true
        ;   catch(check_program_text(Id, Text), error(syntax_error(What), Where),
                  syntax_error_at(Id, Text, What, Where))
        ),
        load_text(Id, Text),
        Reply = ok(loaded(Id))
    ;   node_property(Node, address(Here)),
        Reply = error(error(permission_error(load, platform, Here), _))
    ).

:- multifile prolog:error_message//1.

prolog:error_message(load_errors(Errors)) -->
    [ 'The program did not load cleanly:'-[] ],
    error_lines(Errors).

error_lines([]) --> [].
error_lines([E|Es]) --> [ nl, '  ~w'-[E] ], error_lines(Es).
